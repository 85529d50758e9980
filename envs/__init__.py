"""Gymnasium environments of handsim (imported as ``handsim.envs``)."""
