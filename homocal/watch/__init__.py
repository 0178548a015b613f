"""Watch a deployed camera from the people in view: its horizon over time, its moves, a correction per stretch
(``OnlineCalibrator``; ``homocal watch``)."""
from homocal.watch.calibrator import Move, OnlineCalibrator, State

__all__ = ["Move", "OnlineCalibrator", "State"]
