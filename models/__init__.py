"""The networks and everything that makes an .onnx: log reading, balancing, augmentation, training,
export. PyTorch is imported inside this package only, and only by the modules that need it."""
