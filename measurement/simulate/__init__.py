"""Rig simulator: renders calibration poses and animals under stripes with exact ground truth.

Every test, the demo and every benchmark use it, since no hardware is attached. It models what makes
the real problem hard: lens distortion, defocus, shadows, uneven albedo (chessboard, patchy fur),
fur scatter, specks, dropouts, vignetting, ambient gradients, shot and read noise and quantisation.
"""
