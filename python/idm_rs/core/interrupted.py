"""Ctrl-C in a long call: the call stops and raises KeyboardInterrupt, and what it had finished
travels with the exception (its ``partial`` attribute) where the call's docstring promises it.

A plain KeyboardInterrupt, not a subclass: a script stopped by it exits as any Python script
stopped by Ctrl-C does (status 130 in a shell; CPython gives that only to the exact type)."""

from __future__ import annotations

from typing import Any


def interrupted(message: str, partial: Any) -> KeyboardInterrupt:
    """The KeyboardInterrupt a long call raises on Ctrl-C: ``message`` says where it stopped,
    ``.partial`` holds what it had finished —

    - ``simulate``: the :class:`~idm_rs.SimulationResult` up to the time it stopped
      (``complete`` False, no ``final_state``);
    - ``sweep``: the Dataset with every finished point (the rest NaN, status 0,
      ``attrs["complete"] == 0``); with ``out=`` the Zarr store, which keeps the slabs written;
    - ``characterize``: the Dataset with the curves as far as they ran;
    - ``diagnose``: the :class:`~idm_rs.Diagnosis` of the stages finished (verdict
      ``"interrupted"``), which the report and the figures can show.

    Read it with :func:`partial_result`::

        try:
            ds = idm_rs.sweep(p, w, grid)
        except KeyboardInterrupt as stop:
            ds = idm_rs.partial_result(stop)   # the points finished before Ctrl-C
    """
    exc = KeyboardInterrupt(message)
    setattr(exc, "partial", partial)  # noqa: B010  (KeyboardInterrupt declares no such attribute)
    return exc


def partial_result(exc: BaseException) -> Any:
    """What the interrupted idm-rs call had finished (see :func:`interrupted`), or None for a
    KeyboardInterrupt that did not come from one (or came before anything finished)."""
    return getattr(exc, "partial", None)
