"""Served policies: a method run behind a websocket, evaluated by the harness in another process
or on another machine (``python -m awda_bench serve`` + ``run --method remote``).

- :mod:`.wire`: messages as msgpack, NumPy arrays as dtype + shape + bytes (and why this pair);
- :mod:`.protocol`: the conversation (hello, reset, act, observation requests, errors);
- :mod:`.server`: :class:`~.server.PolicyServer`, the policy's side;
- :mod:`.remote_observations`: the observations a served policy is handed (fetched on request);
- :mod:`.remote_policy`: :class:`~.remote_policy.RemotePolicy`, the harness's side, a
  :class:`~awda_bench.episode.Policy` like any other.

Below the harness: it imports only the episode protocol and the errors.
"""
