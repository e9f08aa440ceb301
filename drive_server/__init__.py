"""Deployment runtime: Socket.IO drive server, ONNX Runtime inference, coupled control law.

Depends only on the design card's packages (never on torch). ``contract`` and ``preprocess`` are
also imported by the training pipeline so training and serving can never drift apart.
"""
