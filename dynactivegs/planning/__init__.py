"""Planning building blocks: motion-aware paths on the Voronoi graph and discrete actions.

- :mod:`~dynactivegs.planning.paths`: edge costs c(e) = len(e) + l_m * mean U_m along e
  (eq. 11), the per-edge temporal EMA of U_m (eq. 13), Dijkstra on a CSR matrix, and the
  planner variants ``shortest | dyn_edge | dyn_edge_temporal``.
- :mod:`~dynactivegs.planning.actions`: a path and target yaw turned into the next discrete
  action, the local collision check against the current depth frame, and a stuck detector.
- :mod:`~dynactivegs.planning.stage`: the planning stage (``PlanningConfig``,
  ``PlanningState``, ``init_state``, ``step``).

NumPy / SciPy / networkx only; never imports torch.
"""
