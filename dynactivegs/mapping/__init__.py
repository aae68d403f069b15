"""The mapping stage: an uncertainty-weighted Gaussian map of the static scene (DESIGN.md §5, Mapping)."""
