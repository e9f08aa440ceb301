"""Closed loop on recorded real frames (``rbc drive-log``): NVIDIA DAVE-2's evaluation of a driving model.

The recorded drive is rebuilt as a path from its speed, steering and frame times; the model drives a car
along it, and sees what the camera would see from the car's own lateral offset and heading error: the
nearest recorded frame re-projected through a ground-plane homography. A person takes over when the car
leaves its lane; the degree of autonomy is the paper's Eq. 1.

Owns: the real simulator's camera model and its calibration from the side cameras (``camera``,
``calibrate``), the recorded path (``path``), the loop and its drivers (``loop``), and its pictures
(``pictures``). May import ``protocol``, ``drive_server`` (the serving pipeline, so the model sees exactly
what the server would give it), ``tools.realdata`` (frame time stamps) and ``tools.sim.rules`` (the
degree of autonomy); never ``models`` or torch.
"""
