"""Measuring the photo chain, in the application layer: what ``deepmorph bench-scenes`` and
``deepmorph bench-photos`` run, and the benchmarks in ``bench/`` call.

* :mod:`~deepmorph.measure.scene_bench`: the whole chain scored on synthetic scenes beside
  ArUco and QR, the morph check's rates, tracking rates; :mod:`~deepmorph.measure.scene_report`
  its text table;
* :mod:`~deepmorph.measure.photo_bench`: a folder of labelled photos scored;
  :mod:`~deepmorph.measure.photo_report` its summary, ``report.html``, ``report.json`` and plots.

What they count with stays in the photo chain: matching to truth (:mod:`deepmorph_detect.metrics`),
the baselines (:mod:`deepmorph_detect.baselines`), scene folders and ``labels.csv``.
"""
