"""Policies (methods) behind one interface; see :mod:`awda_bench.episode`."""
