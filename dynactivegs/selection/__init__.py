"""Selection building blocks: what the robot has seen and where it could look next.

- :mod:`~dynactivegs.selection.occupancy`: a 2D log-odds occupancy grid updated from RGB-D
  frames; returns on uncertain (probably moving) pixels clear space but never become
  obstacles.
- :mod:`~dynactivegs.selection.voronoi`: a Voronoi graph (skeleton of the known free space
  eroded by the robot radius) as a networkx graph, with frontier nodes marked.
- :mod:`~dynactivegs.selection.subregions`: agglomerative clustering of graph nodes with the
  dynamic-aware distance d_dyn of the paper's eq. (6).
- :mod:`~dynactivegs.selection.visibility`: soft visibility of query voxels from candidate
  views and the view gains I_s, R_m (eqs. 8-9).
- :mod:`~dynactivegs.selection.stage`: the selection stage (``SelectionConfig``,
  ``SelectionState``, ``init_state``, ``step``): target keeping, variants, eqs. (7) and (10).

Everything here is NumPy / SciPy / networkx (numba for one kernel) and never imports torch.
"""
