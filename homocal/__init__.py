"""homocal: homography ground-plane mapping, its error model and corrections."""
