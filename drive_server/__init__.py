"""Deployment runtime: Socket.IO drive server, ONNX Runtime inference, coupled control law.

Depends only on the design card's packages (never on torch). The serving contract (``contract``,
``preprocess``, ``smoothing``, ``monitor``, ``model``) is also imported by ``models`` (tests/test_layout.py), so
training and serving can never drift apart.
"""
