"""The shipped default detector weights (default.safetensors + default.json); see docs/MODEL_CARD.md."""
