"""Training the learned methods from collected data: one Table S3 column per ``train`` call.

Data flows one way::

    recipes/<name>.toml --recipe.py--> Recipe      (method, ablation) --columns.py--> Column
    DATA_DIR --awda_bench.data.datasets--> samples --augment.py (shift, jitter, ADM)--> batches
        --loop.py (the resumable loop)--> CKPT_DIR/snapshot-*.pt
        --logbook.py--> metrics.csv, tensorboard/, learning_curve.png
    run.py checks everything first and writes CKPT_DIR/train.json; commands/train.py is the CLI.
"""
