"""The synthetic scene (an object, calibration spheres, a ground) and the capture writer used by tests and the demo."""
