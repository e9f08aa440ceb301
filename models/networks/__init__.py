"""The networks: the layer table shared by torch and the torch-free ONNX builder, the torch modules, checkpoints."""
