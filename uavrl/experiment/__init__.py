"""The library the commands (``python -m uavrl.train|evaluate|render|report|reproduce|bench|benchmarl``) use.

Like BenchMARL's ``benchmarl/experiment/`` under its ``benchmarl/run.py``: each command module ``uavrl/<cmd>.py``
checks its settings without torch, then imports its body here once and calls it:

- ``training`` (``uavrl.train``: the training loop, ``Training``, ``run_training``), ``evaluating``
  (``uavrl.evaluate``: ``evaluate_checkpoint``), ``rendering`` (``uavrl.render``), ``reproducing`` (``uavrl.reproduce``;
  the paper's protocol itself is ``protocol``), ``reporting`` (``uavrl.report``), ``benchmarl`` (``uavrl.benchmarl``:
  ``build_experiment``, ``load_experiment``), ``policy`` (``uavrl.load_policy``'s body);
- what they share: ``saved`` (a saved run read without torch: ``load_agent``, ``output_dir``, the evaluation's check),
  ``runs`` (a new run's directory, eval settings, flat settings, the yardstick's line), ``rundir`` (a run directory's
  lock, interrupts that save), ``checkpoints``, ``io`` (guarded reads, atomic writes), ``logger`` (TensorBoard, GIF
  and MP4 bytes), ``video``, ``plots``, ``missions`` (a mission's batteries).

This package's ``__init__`` imports nothing, and ``io``, ``rundir``, ``runs``, ``checkpoints``, ``saved`` and
``protocol`` import no torch at their top: the commands' checks read them.
"""
