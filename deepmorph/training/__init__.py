"""Training, in the application layer: what ``deepmorph train``, ``train-many``, ``tune-decoder``,
``validate`` and ``train-detector`` run, and :func:`deepmorph.train`.

* :mod:`~deepmorph.training.codec`: the encoder and decoder trained on a drawing (``CodecRun``,
  :func:`~deepmorph.training.codec.train_model`) and a decoder tuned further (``tune_decoder``);
* :mod:`~deepmorph.training.loop`: the one training loop every run above goes through (log,
  checkpoints, resume, interrupts, plot); :mod:`~deepmorph.training.distributed`: devices and
  torchrun's processes; :mod:`~deepmorph.training.code_shrink`: an ``auto`` code made smaller;
* :mod:`~deepmorph.training.many`: a folder of drawings; :mod:`~deepmorph.training.validation`:
  fresh payloads read back after training;
* :mod:`~deepmorph.training.detector` and :mod:`~deepmorph.training.universal`: a model's
  detector and the universal detector, trained on the photo chain's synthetic scenes;
* :mod:`~deepmorph.training.settings` and :mod:`~deepmorph.training.detector_settings`: the
  settings declared once (no torch: the command line reads them to build its options).

The record types a bundle stores (``TrainingRecord``, ``ValidationRecord``, ``AutoPayload``,
``CodeShrink``) stay in :mod:`deepmorph_core.bundle`, so that loading a model needs none of this.
"""
