"""handsim: a MuJoCo simulation of a 27-DoF human hand for depth-based hand pose estimation."""

__version__ = "0.1.0"
