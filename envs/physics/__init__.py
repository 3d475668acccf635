"""The model's physics: geometry, channels, rates, random streams and the parts a :class:`~uavrl.envs.World` is
made of (docs/architecture.md, The World's parts).

- :mod:`.radio`, :mod:`.power`: the channel and energy models' constants, units, sources and ranges (standard
  library only: :mod:`uavrl.envs.config` checks options against them before torch is imported);
- :mod:`.pathloss`: the physical channel models' mean path loss in dB;
- :mod:`.grid`: cells, moves and joint actions; :mod:`.positions`: a model's (cell, altitude level) positions and
  the moves between them; :mod:`.channel`: node layouts, link gains and the AF rates; :mod:`.streams`: the
  per-world counter-based random streams; :mod:`.city`: ITU-R P.1410 cities of buildings and their geometric line of
  sight (numpy only);
- the World's parts: :mod:`.layouts`, :mod:`.fading`, :mod:`.dynamics`, :mod:`.rewards`, :mod:`.energy`,
  :mod:`.buildings` (the city part).

Nothing here imports TorchRL, a solver or the World; this file imports nothing, so the standard-library modules stay
importable without torch.
"""
