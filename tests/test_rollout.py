"""The one rollout loop (``awda_bench.rollout``): hook order and the three ways a rollout ends."""

from __future__ import annotations

from typing import Any

from awda_bench.rollout import SettleAfterDone, roll_out


class _CountingEnv:
    """obs = steps taken; ``info["success"]`` once ``success_at`` steps were taken."""

    def __init__(self, success_at: int = 10**9) -> None:
        self.t = 0
        self.success_at = success_at
        self.actions: list[Any] = []

    def step(self, action: Any) -> tuple[int, float, bool, bool, dict[str, Any]]:
        self.actions.append(action)
        self.t += 1
        return self.t, 0.0, False, False, {"success": self.t >= self.success_at}


def test_hooks_run_in_order_and_max_steps_ends_the_rollout() -> None:
    env, calls = _CountingEnv(), []

    def choose(obs: int) -> str:
        calls.append(("choose", obs))
        return f"a{obs}"

    end = roll_out(
        env.step,
        0,
        choose,
        3,
        before_step=lambda t: calls.append(("before", t)),
        after_step=lambda t, a, info: calls.append(("after", t, a)) is not None,
    )
    assert calls == [
        ("before", 0), ("choose", 0), ("after", 1, "a0"),
        ("before", 1), ("choose", 1), ("after", 2, "a1"),
        ("before", 2), ("choose", 2), ("after", 3, "a2"),
    ]  # fmt: skip
    assert (end.steps, end.obs, env.actions) == (3, 3, ["a0", "a1", "a2"])
    assert end.info == {"success": False}
    assert end.choose_s >= 0.0 and end.step_s >= 0.0


def test_choose_none_ends_before_stepping_and_keeps_the_initial_info() -> None:
    env = _CountingEnv()
    end = roll_out(env.step, "start", lambda obs: None, 5, info={"success": True})
    assert (end.steps, end.obs, end.info, env.actions) == (0, "start", {"success": True}, [])


def test_after_step_true_ends_after_that_step() -> None:
    env = _CountingEnv(success_at=2)
    end = roll_out(env.step, 0, lambda obs: obs, 10, after_step=lambda t, a, info: info["success"])
    assert (end.steps, end.obs, env.actions) == (2, 2, [0, 1])


class _Expert:
    """Done from its ``done_after``-th action on."""

    def __init__(self, done_after: int) -> None:
        self.acted = 0
        self.done_after = done_after

    @property
    def done(self) -> bool:
        return self.acted >= self.done_after

    def act(self, obs: Any) -> int:
        self.acted += 1
        return int(obs)


def test_settle_after_done_steps_settle_steps_more_then_one() -> None:
    # done after its 3rd action; the rollout stops once it has been done for more than 2 steps
    expert, env = _Expert(done_after=3), _CountingEnv()
    end = roll_out(env.step, 0, expert.act, 100, after_step=SettleAfterDone(expert, 2))
    assert end.steps == 3 + 2
    never_done = _Expert(done_after=10**9)
    end = roll_out(
        _CountingEnv().step, 0, never_done.act, 7, after_step=SettleAfterDone(never_done, 2)
    )
    assert end.steps == 7
