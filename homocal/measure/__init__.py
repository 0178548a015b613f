"""Measurements of people on the ground from their tracked boxes: positions, speeds and distances with error
bars (``homocal measure``; docs/measure.md), and ``GroundTracker`` for a live tracker's boxes (supervision's)."""
from homocal.measure.kalman import ACCEL_PSD
from homocal.measure.live import GroundState, GroundTracker
from homocal.measure.tracks import (COLUMNS, TrapezoidMapping, fit_tracks_accel_psd, measure_tracks, pair_distances,
                                   summarise)

__all__ = ["ACCEL_PSD", "COLUMNS", "GroundState", "GroundTracker", "TrapezoidMapping", "fit_tracks_accel_psd",
           "measure_tracks", "pair_distances", "summarise"]
