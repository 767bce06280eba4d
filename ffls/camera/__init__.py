"""Camera models: projection and viewing rays (pinhole with OpenCV distortion), intrinsics calibration."""
