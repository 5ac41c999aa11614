"""Training data for the learned methods: scripted demonstrations and synthesized trajectories.

Data flows one way, mirroring the evaluation path (suite -> specs -> workers -> records -> store)::

    suite + CollectConfig --plan.py--> units, seeded attempts (fixed before scheduling)
        --pool.py (worker processes)--> one CollectJob per unit chunk: fresh env, earlier attempts
          replayed, recorder.py records the next ones: EpisodeData (frames as JPEG)
          (Meta-World: workers from .venv-metaworld, metaworld_recorder.py, the same EpisodeData)
        --trajectory_file.py--> one shard per episode (atomic) --> one ManiSkill file per unit
        --collect.py--> manifest.json (fingerprint, counts)
    DATA_DIR --datasets.py--> torch Datasets in the batch formats of awda_bench.models
    DATA_DIR --info.py--> counts, lengths, disk size, contact sheet

A *unit* is one (role, task): role ``agent`` / ``demonstrator`` (scripted expert of that
embodiment) or ``synthesized`` (trajectory synthesis, recorded by the agent). Each unit ends as
``DATA_DIR/<role>/<family>/task_XX.h5`` + ``.json`` in ManiSkill's trajectory format.
"""
