"""Job execution that evaluation (:mod:`awda_bench.evaluation`) and collection
(:mod:`awda_bench.data`) share: a pool of workers, local processes or Ray actors, each holding
an executor built once, playing jobs and streaming one result per job back to the driver.

- :mod:`.job_pool` is what every pool shares (the executor interface, the watchdog settings,
  :class:`~.job_pool.WorkerStartError`);
- :mod:`.process_pool` the local pool, :mod:`.worker_loop` its workers' side,
  :mod:`.interpreter_process` a worker started from another environment's interpreter
  (Meta-World), :mod:`.parent_death` workers that die with their parent;
- :mod:`.ray_pool` the same on Ray actors;
- :mod:`.backends` the ``--workers``/``--backend``/``--ray-address`` choice of every scheduling
  command.

Nothing here knows what a job is: an episode (:mod:`awda_bench.evaluation.worker_pool`) or a
recording (:mod:`awda_bench.data.pool`).
"""
