"""Every use of rerun-sdk internals, behind one adapter with a public-API fallback.

The Rerun view (:mod:`.rerun_view`) hands Rerun ready Arrow arrays for its heaviest components
(coherence waterfalls, the frequency plots' line strips and points): Rerun's own batch classes
convert in Python at about 0.5 ms per tensor, more than 100 ms per update for 48 pairs. Building
those arrays directly needs two things rerun-sdk does not publish: the Arrow datatype each batch
class keeps in its private ``_ARROW_DATATYPE`` attribute, and the tensor buffer's union variant
per numpy dtype (``rerun.encodings.tensor_data_ext.DTYPE_MAP``).

:func:`arrays` chooses how the arrays are built:

* ``"internal"`` (:class:`InternalArrays`): directly in pyarrow, from those internals, when the
  installed ``rerun.__version__`` is one this module was written for (:data:`KNOWN_VERSIONS`),
  the internals are present and a small sample built that way equals what the public batch
  classes build;
* ``"public"`` (:class:`PublicArrays`) otherwise: through the documented batch classes
  (``rr.components.TensorDataBatch``, ``LineStrip2DBatch``, ``Position2DBatch`` and their
  ``as_arrow_array``); the same arrays, only slower.

The choice is logged once (INFO, this module's logger).
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import pyarrow as pa
import rerun as rr

__all__ = ["KNOWN_VERSIONS", "InternalArrays", "PublicArrays", "arrays", "known_version"]

log = logging.getLogger(__name__)

#: rerun-sdk releases (major.minor) whose internals :class:`InternalArrays` was written for and
#: checked against.
KNOWN_VERSIONS = ("0.41",)

_said: set[str] = set()          # the paths already logged


def known_version(version: str | None = None) -> bool:
    """Whether ``version`` (default: the installed ``rerun.__version__``) is a release in
    :data:`KNOWN_VERSIONS` (any patch release of it)."""
    v = getattr(rr, "__version__", None) if version is None else version
    if not isinstance(v, str):
        return False
    return ".".join(v.split(".")[:2]) in KNOWN_VERSIONS


class PublicArrays:
    """Component Arrow arrays through the documented rerun-sdk batch classes."""

    name = "public"

    @staticmethod
    def tensor(values: np.ndarray, dim_names: tuple | None = None) -> pa.Array:
        """One ``TensorData`` of ``values`` (any numeric dtype Rerun takes), with optional
        dimension names."""
        data = rr.encodings.TensorData(array=values, dim_names=None if dim_names is None else list(dim_names))
        return rr.components.TensorDataBatch(data).as_arrow_array()

    @staticmethod
    def strips(strips: list[np.ndarray]) -> pa.Array:
        """A ``LineStrip2D`` batch: one strip per ``(n_i, 2)`` array of (x, y) points."""
        return rr.components.LineStrip2DBatch([np.asarray(s, np.float32) for s in strips]).as_arrow_array()

    @staticmethod
    def points(xy: np.ndarray) -> pa.Array:
        """A ``Position2D`` batch of the ``(n, 2)`` points ``xy``."""
        return rr.components.Position2DBatch(np.asarray(xy, np.float32).reshape(-1, 2)).as_arrow_array()


class InternalArrays:
    """Component Arrow arrays built directly in pyarrow from rerun-sdk's private datatypes.

    Each method returns exactly what the same method of :class:`PublicArrays` returns. Raises
    ImportError, AttributeError or KeyError on construction when an internal is missing.
    """

    name = "internal"

    def __init__(self) -> None:
        from rerun.encodings.tensor_data_ext import DTYPE_MAP

        tensor_t = rr.components.TensorDataBatch._ARROW_DATATYPE
        self._tensor_fields = list(tensor_t)
        self._shape_t = tensor_t.field("shape").type
        self._names_t = tensor_t.field("names").type
        self._buffer_t = tensor_t.field("buffer").type
        self._buffer_nulls = [pa.nulls(0, type=f.type) for f in self._buffer_t]
        variants = [f.name for f in self._buffer_t]
        self._buffer_idx = {dt: variants.index(name) for dt, name in DTYPE_MAP.items()}
        self._type_id_buf = {i: pa.py_buffer(np.array([i], np.int8)) for i in self._buffer_idx.values()}
        self._offset0_buf = pa.py_buffer(np.array([0], np.int32))
        self._strip_t = rr.components.LineStrip2DBatch._ARROW_DATATYPE
        self._point_t = rr.components.Position2DBatch._ARROW_DATATYPE
        self._shape_array = functools.lru_cache(maxsize=64)(
            lambda shape: pa.array([list(shape)], type=self._shape_t))
        self._names_array = functools.lru_cache(maxsize=64)(
            lambda names: pa.array([None if names is None else list(names)], type=self._names_t))
        self._offsets = functools.lru_cache(maxsize=64)(lambda n: pa.array([0, n], pa.int32()))

    def tensor(self, values: np.ndarray, dim_names: tuple | None = None) -> pa.Array:
        """One ``TensorData`` of ``values``, with optional dimension names.

        ``values`` must not be mutated afterwards (pyarrow wraps the numpy buffer without copying).
        """
        v = np.ascontiguousarray(values)
        idx = self._buffer_idx[v.dtype.type]
        inner = pa.ListArray.from_arrays(self._offsets(v.size), pa.array(v.ravel()), type=self._buffer_t[idx].type)
        children = list(self._buffer_nulls)
        children[idx] = inner
        buffer = pa.Array.from_buffers(type=self._buffer_t, length=1,
                                       buffers=[None, self._type_id_buf[idx], self._offset0_buf], children=children)
        names = None if dim_names is None else tuple(dim_names)
        return pa.StructArray.from_arrays([self._shape_array(v.shape), self._names_array(names), buffer],
                                          fields=self._tensor_fields)

    def strips(self, strips: list[np.ndarray]) -> pa.Array:
        """A ``LineStrip2D`` batch: one strip per ``(n_i, 2)`` array of (x, y) points."""
        flat = np.concatenate(strips).astype(np.float32, copy=False).ravel() if strips else np.zeros(0, np.float32)
        points = pa.FixedSizeListArray.from_arrays(pa.array(flat), type=self._strip_t.value_type)
        offsets = np.zeros(len(strips) + 1, np.int32)
        offsets[1:] = np.cumsum([len(s) for s in strips])
        return pa.ListArray.from_arrays(pa.array(offsets), points, type=self._strip_t)

    def points(self, xy: np.ndarray) -> pa.Array:
        """A ``Position2D`` batch of the ``(n, 2)`` points ``xy``."""
        flat = np.asarray(xy, np.float32).ravel()
        return pa.FixedSizeListArray.from_arrays(pa.array(flat), type=self._point_t)


def _agrees(fast: InternalArrays) -> bool:
    """Whether ``fast`` builds the same arrays as the public batch classes on a small sample of
    every kind the view logs."""
    public = PublicArrays
    xy = np.array([[0.0, 1.0], [2.0, 3.5], [4.0, -1.0]], np.float32)
    cases = [
        (fast.tensor(np.linspace(0.0, 1.0, 7)), public.tensor(np.linspace(0.0, 1.0, 7))),
        (fast.tensor(np.arange(6, dtype=np.uint8).reshape(2, 3), ("a", "b")),
         public.tensor(np.arange(6, dtype=np.uint8).reshape(2, 3), ("a", "b"))),
        (fast.strips([xy, xy[:1]]), public.strips([xy, xy[:1]])),
        (fast.strips([]), public.strips([])),
        (fast.points(xy), public.points(xy)),
    ]
    return all(a.type == b.type and a.equals(b) for a, b in cases)


@functools.lru_cache(maxsize=1)
def _internal() -> tuple[InternalArrays | None, str]:
    """The internal builder, or None and why not (built and checked once per process)."""
    try:
        fast = InternalArrays()
        ok = _agrees(fast)
    except (ImportError, AttributeError, KeyError, TypeError, ValueError, pa.ArrowException) as e:
        return None, f"its internals are missing or changed ({type(e).__name__}: {e})"
    return (fast, "") if ok else (None, "its internals build arrays that differ from the public API's")


def arrays(version: str | None = None) -> InternalArrays | PublicArrays:
    """How to build the view's component arrays with the installed rerun-sdk (module docstring).

    Parameters
    ----------
    version : str, optional
        The rerun-sdk version to decide for (default: ``rerun.__version__``).

    Returns
    -------
    InternalArrays or PublicArrays
        Either has ``tensor``, ``strips`` and ``points``, returning identical ``pyarrow.Array``;
        ``name`` says which (``"internal"`` or ``"public"``).
    """
    v = getattr(rr, "__version__", "unknown") if version is None else version
    if not known_version(v):
        chosen, why = PublicArrays(), f"rerun-sdk {v} is not a version it was written for ({', '.join(KNOWN_VERSIONS)})"
    else:
        fast, why = _internal()
        chosen = PublicArrays() if fast is None else fast
    if chosen.name not in _said:
        _said.add(chosen.name)
        if chosen.name == "internal":
            log.info("Rerun view: Arrow arrays built directly (rerun-sdk %s internals)", v)
        else:
            log.info("Rerun view: Arrow arrays built through the public rerun-sdk API (slower): %s", why)
    return chosen
