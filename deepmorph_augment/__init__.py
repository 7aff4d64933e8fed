"""Differentiable capture corruptions (print-and-photo), each a registered plugin.

One module per corruption (``perspective``, ``scale``, ``rotation``, ``translation``, ``blur``,
``defocus``, ``motion_blur``, ``lighting``, ``intensity``, ``gaussian_noise``, ``salt_pepper``,
``jpeg``), registered by :mod:`deepmorph_augment.plugin`; :mod:`deepmorph_augment.pipeline`
holds the config models, the presets and the ``AugmentPipeline`` module.
"""
