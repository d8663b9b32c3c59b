"""Synthetic operating-room RGB-D scenes in MVOR's layout and schema (see ``docs/synth.md``).

``python -m posenet.synth --out DIR --scenes N --rig random`` renders procedural scenes;
``python -m posenet.synth --out DIR --from-mvor camma_mvor_2018.json`` renders the MVOR twin.
"""

from posenet.synth.writer import SynthConfig, generate

__all__ = ["SynthConfig", "generate"]
