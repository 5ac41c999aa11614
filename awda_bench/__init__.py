"""awda_bench: one-shot visual imitation with attributed waypoints, benchmarked on ManiSkill3.

Data flows one way::

    suite definition (tasks/*.toml) -> seeded episode specs -> workers (env + policy)
        -> episode records -> results store (SQLite) -> tables / figures
"""

__version__ = "0.1.0"
