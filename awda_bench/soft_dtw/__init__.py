"""Soft-DTW (Cuturi & Blondel 2017), the differentiable alignment the waypoint losses are built on:
its values and expected-alignment gradients (:mod:`~awda_bench.soft_dtw.core`), the
anti-diagonal tables they are computed with (:mod:`~awda_bench.soft_dtw.tables`) and a fused
Triton kernel for CUDA (:mod:`~awda_bench.soft_dtw.triton_kernel`). Knows nothing of robots or
networks: it imports only :mod:`awda_bench.errors`."""
