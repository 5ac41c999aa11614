"""``reproduce``: from an empty directory to Table S3/S4 rows, one resumable command.

::

    OUT/data/train        collect --split train   (agent + demonstrator episodes, synthesized;
                                                   --data DIR: that collection instead)
    OUT/data/test         collect --split test    (validation pairs; pick-place only)
    OUT/checkpoints/COL   train  (one Table S3 column each: snapshots every M steps)
    OUT/runs              run    (last N snapshots x the protocol's episodes, one store, the
                                  column's key as the method label); Full-1 also on two training
                                  tasks ("full-1 (train tasks)") to tell a failure to generalize
                                  from a failure to fit
    OUT/report            report (tables, figures, summary.json) + reproduce.md (scale vs paper)

Every stage is an ordinary command (``collect``, ``train``, ``run``, ``report``) run as a
subprocess with its arguments printed, and every one of them resumes by itself: a re-run skips
finished collections (their manifest is complete and describes the same request), finished training
runs (the last snapshot is at the recipe's step) and evaluated episodes (the store holds them for
the same protocol fingerprint, label and snapshot hash). Before anything runs, the plan is printed
with an estimated wall time per stage from the per-unit costs in
:data:`~awda_bench.reproduce.costs.COSTS` (measured on the 2-core CPU machine this project is
developed on; a GPU trains much faster). What is left is read
through the functions the commands themselves call, from the config each ``collect`` and ``run``
stage's command line decides (:class:`~awda_bench.data.config.CollectConfig`,
:class:`~awda_bench.evaluation.sweep.SweepConfig`; ``Stage.config``).

Modules, each importing only those above it:

- :mod:`~awda_bench.reproduce.config`: what ``reproduce`` decides (suites, ``--columns`` names,
  :class:`~awda_bench.reproduce.config.ReproduceConfig`);
- :mod:`~awda_bench.reproduce.costs`: the per-unit wall times of the estimate;
- :mod:`~awda_bench.reproduce.plan`: the stages, their command lines and estimates;
- :mod:`~awda_bench.reproduce.stages`: running them, the lock and ``OUT/stage_times.json``;
- :mod:`~awda_bench.reproduce.summary`: ``OUT/report/reproduce.md`` and the re-run command line.
"""
