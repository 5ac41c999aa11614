"""Meta-World (the ``metaworld`` package, its Sawyer arm and 50 tasks) as a harness simulator.

Everything here runs inside workers started from ``.venv-metaworld`` (see
:mod:`awda_bench.runtimes`: Meta-World's MuJoCo cannot share the project's environment); nothing
in the main environment imports this package (the task names it checks suite files against are
:mod:`awda_bench.metaworld_tasks`). Rendering is headless: MuJoCo's EGL backend (Mesa's
software renderer without a GPU) unless ``MUJOCO_GL`` says otherwise, chosen here before anything
imports ``mujoco``.

- :mod:`.layout`: one task's env and the seeded layouts;
- :mod:`.renderer`: one MuJoCo renderer per process, any camera, RGB upright and depth in metres;
- :mod:`.env`: a suite's tasks behind the harness's env interface;
- :mod:`.observations`: what an observation-only policy sees;
- :mod:`.expert`: the package's scripted policies as the ``scripted`` method;
- :mod:`.rollout`: the expert played from a state as a recorded trajectory (plans, collection);
- :mod:`.demo`: the demonstration video (the expert in the demo layout);
- :mod:`.state`: save and restore a task env exactly;
- :mod:`.sawyer`: the Sawyer as the motor primitives' robot (state, mocap driver, parameters);
- :mod:`.sawyer_interface`: that robot in one episode, read through its observations (what
  ``awda`` drives, and ``gt-waypoints`` executes with);
- :mod:`.gt_scene`: what ``gt-waypoints`` needs of an episode (the plan, the wrist localizer).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
