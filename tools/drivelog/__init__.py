"""Closed loop on recorded real frames (``rbc drive-log``): NVIDIA DAVE-2's evaluation of a driving model.

The recorded drive is rebuilt as a path from its speed, steering and frame times; the model drives a car
along it, and sees what the camera would see from the car's own lateral offset and heading error: the
nearest recorded frame of the nearest camera re-projected through a ground-plane homography. A person takes
over when the car leaves the road, whose edges are found in every recorded frame; the degree of autonomy is
the paper's Eq. 1.

Owns: the real simulator's camera model (its numbers and pinhole maths are :mod:`protocol.camera`'s) and its
calibration from the side cameras (``camera``, ``calibrate``), the ground's pitch in every frame (``pitch``), the
recorded path (``path``), the road's edges and each track's profile (``road``, ``road_view``, ``track``), the loop
and its drivers (``loop``), the one assembly of a closed loop on a recording that every command uses (``run``),
driving chosen rows only (``rows``), and its pictures (``pictures``, ``road_picture``). May import ``protocol``
(the camera, frame time stamps), ``drive_server`` (the serving pipeline, so the model sees exactly what the
server would give it), ``tools.sim.driving.rules`` (the degree of autonomy), ``models.data.labels`` (numpy only)
and, to draw a training run's held-out rows again, ``models.data.trainingdata`` and
``models.training.train_config`` (no torch); never torch, and never ``tools.realdata`` (which drives recordings
through here: ``rbc data crossval``).

Why not MIT's VISTA (``vista`` 2.0.6 on PyPI, the field's data-driven simulator): its sdist declares no
dependencies but imports pyrender (OpenGL, so EGL or OSMesa on a headless machine) and ffio (an ffmpeg
reader); a trace must be an H.264 video with CAN, GPS and IMU files and a camera calibration, so every
Udacity log would first be converted; and its monocular view synthesis is the same ground-plane
re-projection done here, rendered as a mesh with OpenGL. Here it is a ``cv2.remap`` of each recorded
JPEG, runs on the deployment packages alone, and reads the logs as the simulator wrote them.
"""
