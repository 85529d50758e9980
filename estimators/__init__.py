"""Pose estimators of handsim (imported as ``handsim.estimators``); torch is imported lazily."""
