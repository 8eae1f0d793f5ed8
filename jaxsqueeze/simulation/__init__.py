"""Squeeze layer: scene and settings, contact laws, the staged event loop, statuses and the
result. Depends on :mod:`jaxsqueeze.geometry` and :mod:`jaxsqueeze.mechanics`."""
