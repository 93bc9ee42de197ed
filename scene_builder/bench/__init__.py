"""The evaluation layer: everything that measures the product, nothing the product runs on.

One module per concern (none imported here, so ``import scene_builder.bench.x`` loads only x):

* :mod:`~scene_builder.bench.procedural` decides a room with exact ground truth from a seed;
  :mod:`~scene_builder.bench.render` builds it in MuJoCo and writes a sample folder (also the
  input of ``scene-builder demo``); :mod:`~scene_builder.bench.truth` reads ground truth back and
  scores a built scene against it.
* :mod:`~scene_builder.bench.metrics`: box, matching and object scores.
* :mod:`~scene_builder.bench.suites`: ``scene-builder bench`` (synthetic and real suites, the
  pipeline against :mod:`~scene_builder.bench.baseline`, the naive baseline).
* :mod:`~scene_builder.bench.report`: bench JSON and the stage benchmarks as BENCHMARKS.md.
* Stage benchmarks (``python -m scene_builder.bench.NAME``): :mod:`~scene_builder.bench.depth`
  (depth backends on real RGB-D), :mod:`~scene_builder.bench.perception` (segmentation and naming
  on procedural rooms), :mod:`~scene_builder.bench.assets` (shape-prior generator),
  :mod:`~scene_builder.bench.tokens` (PhysX token encodings), :mod:`~scene_builder.bench.solver`
  (layout solver on clutter).
* Synthetic inputs for those benchmarks and the stage tests:
  :mod:`~scene_builder.bench.synthetic_boxes` (half-observed boxes as a Perception) and
  :mod:`~scene_builder.bench.clutter` (assets with exact mass properties, dropped overlapping).

This package may import every stage; no stage imports it.
"""
