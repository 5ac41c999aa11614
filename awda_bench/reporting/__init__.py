"""Reporting: the results store's rows turned into what is read.

- :mod:`.aggregate` (cells: mean, standard error, per family), :mod:`.bootstrap_ci` (stratified
  bootstrap intervals), :mod:`.tables` (Markdown and LaTeX);
- :mod:`.report` writes a run's tables and figures (``python -m awda_bench report``);
- :mod:`.results_index`, :mod:`.results_page` and :mod:`.paper_values` build the results page
  (``reports/RESULTS.md``) with the paper's values beside ours;
- :mod:`.figures` (curves, waypoint overlays, paths, PNG/MP4), :mod:`.videos` (episodes recorded
  as videos), :mod:`.synthesis_figure` (Fig. S6, a collection's synthesized trajectories).
"""
