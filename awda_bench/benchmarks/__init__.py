"""Measurements: one module per ``python -m awda_bench bench NAME``, above everything it measures.

==============  ===================================================================================
module          what it measures
==============  ===================================================================================
controller      mink IK vs ManiSkill's IK vs joint targets, env steps/s (``--fidelity``:
                :mod:`.controller_fidelity`, what the 4-D action does)
env             task env steps/s with the scripted expert, the cost of a rendered frame, expert
                success sweeps
primitives      primitive + executor overhead per env step, wrist-depth localization, attribute
                mining against simulator truth
throughput      ``bench harness``: episodes/minute per worker count and backend, harness overhead,
                beside the machine's own ceiling (:mod:`.core_scaling`)
episode_cost    ``bench episode-cost``: wall time, rendered frames and inference of one episode
render_cost     ``bench render-cost``: a frame's render time per render body, and with the robot's
                visual meshes decimated
inference       a learned model's forward-pass latency
soft_dtw        the multi-waypoint Soft-DTW loss per implementation (and its share of a step)
metaworld       Meta-World frames (the models' render settings vs fast) and the scripted policies'
                lengths, in ``.venv-metaworld``
==============  ===================================================================================

:mod:`awda_bench.commands.bench` wires them to the command line, importing only the chosen one.
"""
