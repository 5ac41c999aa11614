"""A 95 % confidence interval for a success rate averaged over snapshots: a stratified bootstrap.

A cell's statistic is the mean over its snapshots of each snapshot's success rate (as in
:mod:`awda_bench.reporting.aggregate`); for a cell averaged over task families too (Table S4's All),
the mean over families of that. Each snapshot's episode outcomes (0/1) are one sample;
:func:`scipy.stats.bootstrap` with ``paired=False`` resamples every sample on its own (with
replacement, keeping its size), which is a bootstrap stratified by snapshot::

    snapshot 1   1 1 0 1 ... 1   (n1 episodes)  -> resample n1 of them  -> rate 1 ┐
    snapshot 2   0 1 1 1 ... 0   (n2 episodes)  -> resample n2 of them  -> rate 2 ├ mean = one
    ...                                                                           │ bootstrap
    snapshot k   1 0 0 1 ... 1   (nk episodes)  -> resample nk of them  -> rate k ┘ statistic

The snapshots themselves are held fixed: the interval measures how much the cell would move with
other episodes of the same snapshots, not with other snapshots (the SE over snapshots does that).

Percentile intervals (BCa fails on samples that are all 0 or all 1); when every sample is
constant, every resample is the same and the interval is ``[p, p]`` without resampling. The
random state is fixed, so a page built twice from the same rows prints the same interval.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

CONFIDENCE_LEVEL = 0.95
"""Two-sided coverage of the interval."""

N_RESAMPLES = 9999
"""Bootstrap resamples (scipy's default)."""

RANDOM_STATE = 0
"""Seed of the resampling (``scipy.stats.bootstrap(random_state=...)``)."""


def outcomes(successes: int, episodes: int) -> np.ndarray:
    """The 0/1 outcome vector of ``episodes`` ok episodes, ``successes`` of them successful
    (order does not matter to a bootstrap of the mean)."""
    if not 0 <= successes <= episodes:
        raise ValueError(f"need 0 <= successes <= episodes, got {successes} of {episodes}")
    return np.r_[np.ones(successes), np.zeros(episodes - successes)]


def stratified_mean(strata: Sequence[Sequence[np.ndarray]]) -> float:
    """Mean over strata (families) of the mean over samples (snapshots) of each sample's mean."""
    return float(np.mean([np.mean([s.mean() for s in samples]) for samples in strata]))


def stratified_bootstrap_ci(strata: Sequence[Sequence[np.ndarray]]) -> tuple[float, float]:
    """95 % percentile CI of :func:`stratified_mean` (module docstring).

    ``strata``: one sequence of samples per family (a single family for a one-suite cell); each
    sample is one snapshot's 0/1 episode outcomes, with at least one episode.
    """
    if not strata or any(not samples for samples in strata):
        raise ValueError("every stratum needs at least one sample")
    if any(s.size == 0 for samples in strata for s in samples):
        raise ValueError("every sample needs at least one episode")
    point = stratified_mean(strata)
    if all(np.all(s == s[0]) for samples in strata for s in samples):
        return point, point
    sizes = [len(samples) for samples in strata]
    # scipy needs two observations per sample; resampling [x] and [x, x] both always give x
    flat = [np.repeat(s, 2) if s.size == 1 else s for samples in strata for s in samples]

    def statistic(*data: np.ndarray, axis: int) -> np.ndarray:
        means = [np.mean(d, axis=axis) for d in data]
        per_stratum, start = [], 0
        for size in sizes:
            per_stratum.append(np.mean(means[start : start + size], axis=0))
            start += size
        return np.asarray(np.mean(per_stratum, axis=0))

    result = stats.bootstrap(
        flat,
        statistic,
        n_resamples=N_RESAMPLES,
        vectorized=True,
        paired=False,
        confidence_level=CONFIDENCE_LEVEL,
        method="percentile",
        random_state=RANDOM_STATE,
    )
    ci = result.confidence_interval
    return float(ci.low), float(ci.high)
