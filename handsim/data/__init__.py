"""Data out of handsim: generation, shards and manifest, the torch ``Dataset``, exports.

This package holds what turns rendered Frames into datasets (HDF5 shards with a manifest, a
lazily imported torch ``Dataset``) and into the formats other tools read (Minari, BOP, hand
labels). It imports neither the envs nor torch at import time.
"""
