"""The evaluation: suite -> seeded episode specs -> workers -> records -> store.

Each arrow is one module:

- :mod:`.episode_specs` fixes the episode list and the protocol fingerprint before scheduling;
- :mod:`.methods` turns a method name (and a snapshot) into a
  :class:`~awda_bench.episode.Policy` (``remote``: a policy served elsewhere,
  :mod:`awda_bench.serving`);
- :mod:`.env_factory` builds the one env a worker reuses;
- :mod:`.episode_runner` plays one episode into an :class:`.episode_record.EpisodeRecord`;
- :mod:`.worker_pool` runs episodes in processes with a watchdog, on the local pool that
  ``collect`` uses too (:mod:`awda_bench.execution`); :mod:`.episode_pools` picks the pool of a
  backend (local processes, or Ray actors);
- :mod:`.results_store` keeps one SQLite row per episode, keyed for resume;
- :mod:`.sweep` ties them together for ``python -m awda_bench run``.

The rows become tables, figures and the results page in :mod:`awda_bench.reporting`.
"""
