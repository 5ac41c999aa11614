"""Two methods of your own for ``awda_bench``, written against its documented policy API only
(:mod:`awda_bench.episode`): nothing here reads the simulator.

- :mod:`.wrist_descend` (non-learned): descends on whatever the wrist depth camera sees below it,
  closes the gripper, lifts.
- :mod:`.demo_reacher` (learned, its own checkpoint format): a linear map from the demonstration's
  colour change to a TCP goal, one ``snapshot-<step>.npz`` per snapshot.

Run them (from the repository root)::

    PYTHONPATH=examples python -m awda_bench run --suite pick_place \\
        --method awda_example_policies.wrist_descend:WristDescendPolicy --episodes 1
    PYTHONPATH=examples python -m awda_example_policies.make_checkpoints ckpt/demo_reacher
    PYTHONPATH=examples python -m awda_bench run --suite pick_place \\
        --method awda_example_policies.demo_reacher:DemoReacherPolicy \\
        --checkpoints ckpt/demo_reacher --snapshots 2 --episodes 1
"""
