"""Fields stage: structural and motion uncertainty on a voxel query grid (DESIGN.md §5 Fields).

- :mod:`~dynactivegs.fields.grid`: the growing voxel grid Omega and the per-frame update of
  the effective observation count n_t, the aggregated render residual e_t and the motion
  uncertainty U_m (eqs. 4-5), vectorised over the voxels near the camera.
- :mod:`~dynactivegs.fields.stage`: ``FieldsConfig``, ``FieldsState``, ``init_state`` and
  ``step`` in the stage contract of DESIGN.md §3.
- :mod:`~dynactivegs.fields.project`: U_m of a :class:`~dynactivegs.records.FieldsOut` as a
  2D floor map and its samples at floor points (for subregions and planning).

NumPy only; never imports torch.
"""

from dynactivegs.fields.stage import FieldsConfig, FieldsState, init_state, step

__all__ = ["FieldsConfig", "FieldsState", "init_state", "step"]
