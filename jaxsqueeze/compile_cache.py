"""Opt-in persistent compilation cache: a second process reuses the compiled squeeze (DESIGN 2.10).

A squeeze program takes seconds to compile on a CPU. JAX can keep compiled programs on disk
and load them in the next process instead of compiling again. The library never turns this on
by itself (DESIGN 4: no global JAX config at import); call :func:`enable` once at the start of
a script or notebook::

    import jaxsqueeze as jsq
    from jaxsqueeze import compile_cache
    compile_cache.enable()            # ~/.cache/jaxsqueeze/jax, or $JAXSQUEEZE_CACHE
    res = jsq.squeeze(scene)          # compiles once; the next process loads it from disk

The command line enables it by default, and so does every worker of
:func:`jaxsqueeze.batch.map_scenes`.

What it sets, and nothing else:

* ``jax_compilation_cache_dir``: the cache folder;
* ``jax_persistent_cache_min_compile_time_secs``: only programs that took at least this long
  to compile are written (default 0.5 s here, JAX's own default is 1 s): the squeeze program is
  cached even on a fast machine, the many tiny eager programs are not;
* ``jax_persistent_cache_min_entry_size_bytes``: ``-1`` (no size limit, no override by JAX).

The cache is trusted code: do not point it at a folder that others can write to.
"""
from __future__ import annotations

import math
import numbers
import os

ENV = "JAXSQUEEZE_CACHE"
MIN_COMPILE_TIME_S = 0.5


def default_path() -> str:
    """``$JAXSQUEEZE_CACHE`` if set, else ``~/.cache/jaxsqueeze/jax`` (``$XDG_CACHE_HOME`` honoured)."""
    env = os.environ.get(ENV)
    if env:
        return os.path.abspath(os.path.expanduser(env))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "jaxsqueeze", "jax")


def enable(path: str | os.PathLike | None = None, *, min_compile_time_s: float = MIN_COMPILE_TIME_S) -> str:
    """Turn on JAX's persistent compilation cache at ``path`` and return the folder used.

    Args:
        path: the cache folder (created if missing). ``None``: :func:`default_path`.
        min_compile_time_s: programs compiled faster than this are not written.

    Idempotent: a second call with the same folder changes nothing. A call with another folder
    moves the cache there (programs already loaded in this process stay loaded). Only the three
    cache options above are set; precision and every other JAX option are left alone.
    """
    import jax

    if path is not None and not isinstance(path, (str, os.PathLike)) or path == "":
        raise TypeError(f"compile_cache.enable: path={path!r} must be a folder name (str or path), or None for "
                        f"the default ({default_path()})")
    t = min_compile_time_s
    if isinstance(t, bool) or not isinstance(t, numbers.Real) or not (math.isfinite(t) and t >= 0):
        raise ValueError(f"compile_cache.enable: min_compile_time_s={t!r} must be a finite number of seconds >= 0")
    path = os.path.abspath(os.path.expanduser(os.fspath(path))) if path is not None else default_path()
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ValueError(f"compile_cache.enable: cannot use {path!r} as the cache folder ({e.strerror}); pass a "
                         "writable folder") from None
    current = jax.config.jax_compilation_cache_dir
    if current is not None and os.path.abspath(current) == path and enabled() \
            and jax.config.jax_persistent_cache_min_compile_time_secs == min_compile_time_s:
        return path
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    jax.config.update("jax_compilation_cache_dir", path)
    if current is not None and os.path.abspath(current) != path:
        _reset()      # JAX opens its cache once per process: reopen it at the new folder
    return path


def enabled() -> str | None:
    """The cache folder if the persistent cache is on in this process, else ``None``."""
    import jax
    path = jax.config.jax_compilation_cache_dir
    return path if path and jax.config.jax_enable_compilation_cache else None


def _reset() -> None:
    try:
        from jax.experimental.compilation_cache import compilation_cache as cc
        cc.reset_cache()
    except Exception:   # noqa: BLE001  (an older or newer JAX without it: the new folder applies to new processes)
        pass


__all__ = ["ENV", "MIN_COMPILE_TIME_S", "default_path", "enable", "enabled"]
