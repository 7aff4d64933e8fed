"""Detectors, keypoints, pose and rectification (the next stage).

Detectors implement :class:`deepmorph_core.protocols.Detector` and register through the
``deepmorph_register_detectors`` hook like every other plugin. No detector ships yet: until one
does, ``deepmorph decode`` reads images in which the drawing roughly fills the frame.
"""
