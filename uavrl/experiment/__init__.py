"""The library the commands (``python -m uavrl.train|evaluate|render|report|reproduce|bench|benchmarl``) use.

Like BenchMARL's ``benchmarl/experiment/`` under its ``benchmarl/run.py``: each command module ``uavrl/<cmd>.py``
checks its settings without torch, then calls its body here:

- ``training`` (``uavrl.train``: the training loop, ``Training``), ``evaluating`` (``uavrl.evaluate``:
  ``load_agent``, ``output_dir``, the evaluation of a checkpoint), ``rendering`` (``uavrl.render``),
  ``reproducing`` (``uavrl.reproduce``), ``reporting`` (``uavrl.report``), ``benchmarl`` (``uavrl.benchmarl``:
  ``build_experiment``, ``load_experiment``);
- what they share: ``runs`` (a new run's directory, eval settings, flat settings, the yardstick's line), ``rundir``
  (a run directory's lock, interrupts that save), ``checkpoints``, ``io`` (guarded reads, atomic writes),
  ``logger`` (TensorBoard), ``video``, ``plots``.

This package's ``__init__`` imports nothing, so the torch-free modules (``io``, ``rundir``, ``runs``) load without
torch.
"""
