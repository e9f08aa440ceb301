"""ONNX files: export from torch, metadata, and graph edits (mirror average, ensemble, peer import, card)."""
