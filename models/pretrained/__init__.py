"""Bundled pretrained models (``simplistic.onnx`` and friends), shipped as package data.

A package (not a bare folder) so the drive server can find them with ``importlib.resources`` in an
installed wheel as well as in a source checkout. Must stay free of imports: the drive server reads
this package and never imports torch.
"""
