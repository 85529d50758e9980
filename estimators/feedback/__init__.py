"""handsim feedback loop (Oberweger et al. 2015): synthesizers, updater, estimator."""
