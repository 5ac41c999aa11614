"""The evaluation harness: suite -> seeded episode specs -> workers -> records -> store -> report.

Each arrow is one module:

- :mod:`.episode_specs` fixes the episode list and the protocol fingerprint before scheduling;
- :mod:`.methods` turns a method name (and a snapshot) into a
  :class:`~awda_bench.episode.Policy` (``remote``: a policy served elsewhere,
  :mod:`awda_bench.serving`);
- :mod:`.env_factory` builds the one env a worker reuses;
- :mod:`.episode_runner` plays one episode into an :class:`.episode_record.EpisodeRecord`;
- :mod:`.worker_pool` runs episodes in processes with a watchdog (:mod:`.job_pool` is what every
  pool shares, :mod:`.process_pool` the local pool ``collect`` uses too, :mod:`.worker_loop` its
  workers' side, :mod:`.interpreter_process` a worker started from another environment's
  interpreter (Meta-World), :mod:`.ray_pool` the same on Ray actors; :mod:`.backends` picks one);
- :mod:`.results_store` keeps one SQLite row per episode, keyed for resume;
- :mod:`.sweep` ties them together for ``python -m awda_bench run``;
- :mod:`.aggregate`, :mod:`.tables`, :mod:`.figures`, :mod:`.report` turn the rows into tables.
"""
