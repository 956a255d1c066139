"""Rendering on a Dask cluster (``pip install 'drt-renderer[farm]'``; docs/farm.md).

- ``plan``: cutting frames into tasks (tiles, then sample ranges), no Dask;
- ``tasks``: what a worker runs (``render_task``), a pure function, no Dask;
- ``client``: connecting, scattering scenes, submitting, merging, time-outs: the only module
  that imports ``distributed``, and only when a cluster is named.

Importing ``drt.farm`` imports no Dask; ``render_frames``, ``connect`` and ``FarmError`` come
from ``drt.farm.client``.
"""
