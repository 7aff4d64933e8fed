"""Finding drawings in photos: detection, alignment, rectification, pose, fusion, scenes.

* :mod:`~deepmorph_detect.network`: the detector CNN (trained on synthetic scenes by the
  application layer's :mod:`deepmorph.training.detector`, ``deepmorph train-detector``).
* :mod:`~deepmorph_detect.locate`: the chain from a photo to decoded drawings with keypoints,
  homography and pose; :mod:`~deepmorph_detect.refine`: sub-pixel alignment and verification.
* :mod:`~deepmorph_detect.verifier`: a model's proposal verifier, which turns other drawings
  the universal detector proposes away before the wider alignment searches (trained by
  :mod:`deepmorph.training.verifier`, ``deepmorph train-verifier``).
* :mod:`~deepmorph_detect.camera`: intrinsics, calibration files and PnP.
* :mod:`~deepmorph_detect.fusion`: fusing a drawing's bits over the frames of a video.
* :mod:`~deepmorph_detect.scenes`: the capture simulator (``deepmorph synth``); what scores the
  chain on its scenes and on labelled photos (``bench-scenes``, ``bench-photos``) is the
  application layer's (:mod:`deepmorph.measure`).

Detectors implement :class:`deepmorph_core.protocols.Detector` and register through the
``deepmorph_register_detectors`` hook like every other plugin.
"""
