"""Misbehaviour monitors for drive_server (:mod:`drive_server.serving.monitor`): trained, calibrated on nominal
driving and attached to a steering model's file here; served there without torch."""
