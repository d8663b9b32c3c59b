"""Training presets of the pose network, one json per preset (read by ``posenet.training.train``)."""
