"""Differentiable capture corruptions (print-and-photo), each a registered plugin.

One module per corruption (``perspective``, ``scale``, ``rotation``, ``translation``, ``blur``,
``defocus``, ``motion_blur``, ``lighting``, ``intensity``, ``gaussian_noise``, ``salt_pepper``,
``jpeg``, and ``colour``: ink fade, paper tint, white balance and chroma subsampling on RGB),
registered by :mod:`deepmorph_augment.plugin`. The pipeline that composes them is core's
(:mod:`deepmorph_core.corruption`), and so is the severity table that configures them
(:mod:`deepmorph_core.severity`).
"""
