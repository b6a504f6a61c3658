"""planecal: joint-offset calibration on a plane, with a MuJoCo digital twin test bench."""

__version__ = "0.1.0"
