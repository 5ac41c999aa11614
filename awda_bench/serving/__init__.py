"""Served policies: a method run behind a websocket, evaluated by the harness in another process
or on another machine (``python -m awda_bench serve`` + ``run --method remote``), over
awda_bench's own protocol or openpi's (``--protocol openpi``).

- :mod:`.wire`: messages as msgpack, NumPy arrays as dtype + shape + bytes (and why this pair),
  in both protocols' key flavours;
- :mod:`.connection`: the harness's connection to a server and its one-line failures;
- :mod:`.protocol`: the native conversation (hello, reset, act, observation requests, errors);
- :mod:`.server`: :class:`~.server.PolicyServer`, the policy's side;
- :mod:`.remote_observations`: the observations a served policy is handed (fetched on request);
- :mod:`.remote_policy`: :class:`~.remote_policy.RemotePolicy`, the harness's side, a
  :class:`~awda_bench.episode.Policy` like any other;
- :mod:`.openpi_schema`: openpi's protocol here: the observation dict, the reply, the metadata;
- :mod:`.openpi_policy`: :class:`~.openpi_policy.OpenpiPolicy`, the harness as an openpi client;
- :mod:`.openpi_adapter`: :class:`~.openpi_adapter.OpenpiAdapter`, one of our policies as an
  openpi policy (``infer``), for any openpi server;
- :mod:`.openpi_server`: :class:`~.openpi_server.OpenpiServer`, ``serve --protocol openpi``.

Below the harness: it imports only the episode protocol and the errors.
"""
