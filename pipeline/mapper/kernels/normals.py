"""Standard normals from numpy's PCG64 with its ziggurat, inlined: the same numbers, faster.

The particle correction draws ~130 M normals per hour of a 16-sonar ring. numba's
``Generator.standard_normal`` runs numpy's algorithm but reaches the bit generator through
its function pointer for every 64-bit word (~3.6 ns a draw); here the generator's step is
inlined (:func:`_step`, 128-bit LCG arithmetic in LLVM's ``i128``) and its state kept in
registers: 2.6 ns a draw against 3.7 ns, measured on this machine.

Exactly numpy's stream: ``PCG64`` is PCG XSL-RR 128/64 (state ← state · M + inc, then the
new state's ``rotr64(hi ^ lo, hi >> 58)``); ``standard_normal`` is numpy's
``random_standard_normal`` (the ziggurat of ``numpy/random/src/distributions``, whose
tables numba ships and uses for its own ``standard_normal``), with doubles as
``(next64 >> 11) · 2⁻⁵³``. :func:`pcg64_words` takes a ``Generator``'s state out as four
``uint64`` (state hi, lo, increment hi, lo) and :func:`set_pcg64_words` puts it back, so
the generator continues as if it had drawn the numbers itself (the tests compare streams
and states with numpy's).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numba.np.random._constants import (  # numba's copy of numpy's ziggurat tables
    fi_double,
    ki_double,
    wi_double,
    ziggurat_nor_inv_r,
    ziggurat_nor_r,
)

# PCG_DEFAULT_MULTIPLIER_128 of numpy's pcg64.h.
_MULT = (2549297995355413924 << 64) + 4865540595714422341
_MASK64 = (1 << 64) - 1


def _step_typing(typingctx: Any, s_hi: Any, s_lo: Any, i_hi: Any, i_lo: Any) -> Any:
    """``state · M + inc`` mod 2¹²⁸ on (hi, lo) uint64 halves; returns the new (hi, lo)."""
    u64 = types.uint64
    sig = types.UniTuple(u64, 2)(u64, u64, u64, u64)  # type: ignore[no-untyped-call]

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        w = ir.IntType(128)
        sixty_four = ir.Constant(w, 64)

        def wide(hi: Any, lo: Any) -> Any:
            return builder.or_(builder.shl(builder.zext(hi, w), sixty_four), builder.zext(lo, w))

        new = builder.add(builder.mul(wide(args[0], args[1]), ir.Constant(w, _MULT)),
                          wide(args[2], args[3]))
        hi = builder.trunc(builder.lshr(new, sixty_four), ir.IntType(64))
        lo = builder.trunc(new, ir.IntType(64))
        return context.make_tuple(builder, signature.return_type, (hi, lo))

    return sig, codegen


_step: Any = intrinsic(_step_typing)  # called from kernels as _step(hi, lo, inc_hi, inc_lo)


@njit(cache=True, inline="always")
def _output(hi: np.uint64, lo: np.uint64) -> np.uint64:
    """XSL-RR: the 64-bit word of a (new) 128-bit state."""
    x = hi ^ lo
    rot = hi >> np.uint64(58)
    return (x >> rot) | (x << ((np.uint64(64) - rot) & np.uint64(63)))


@njit(cache=True, inline="always")
def _double(hi: np.uint64, lo: np.uint64) -> float:
    """numpy's ``next_double`` from the word of state (hi, lo): 53 bits · 2⁻⁵³."""
    return float(_output(hi, lo) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def fill_standard_normal(st: np.ndarray, out: np.ndarray) -> None:
    """``out[i]`` = the next draws of numpy's ``Generator.standard_normal``, in order (its
    ziggurat, branch for branch); ``st`` (:func:`pcg64_words`) is advanced. The state lives
    in locals, so the loop keeps it in registers."""
    hi, lo, inc_hi, inc_lo = st[0], st[1], st[2], st[3]
    n = out.shape[0]
    i = 0
    while i < n:
        hi, lo = _step(hi, lo, inc_hi, inc_lo)
        r = _output(hi, lo)
        idx = r & np.uint64(0xFF)
        r >>= np.uint64(8)
        rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = float(rabs) * wi_double[idx]
        if r & np.uint64(1):
            x = -x
        if rabs < ki_double[idx]:
            out[i] = x
            i += 1
        elif idx == 0:  # the tail beyond ziggurat_nor_r
            while True:
                hi, lo = _step(hi, lo, inc_hi, inc_lo)
                xx = -ziggurat_nor_inv_r * math.log1p(-_double(hi, lo))
                hi, lo = _step(hi, lo, inc_hi, inc_lo)
                yy = -math.log1p(-_double(hi, lo))
                if yy + yy > xx * xx:
                    out[i] = -(ziggurat_nor_r + xx) if (rabs >> np.uint64(8)) & np.uint64(1) \
                        else ziggurat_nor_r + xx
                    i += 1
                    break
        else:  # the wedge: accept against the density, else draw again
            hi, lo = _step(hi, lo, inc_hi, inc_lo)
            if ((fi_double[idx - 1] - fi_double[idx]) * _double(hi, lo) + fi_double[idx]
                    < math.exp(-0.5 * x * x)):
                out[i] = x
                i += 1
    st[0] = hi
    st[1] = lo


def pcg64_words(rng: np.random.Generator) -> np.ndarray:
    """The ``PCG64`` generator's state as uint64 [state hi, lo, increment hi, lo]."""
    s = rng.bit_generator.state
    if s["bit_generator"] != "PCG64":
        raise TypeError(f"expected a PCG64 generator, got {s['bit_generator']}")
    state, inc = s["state"]["state"], s["state"]["inc"]
    return np.array([state >> 64, state & _MASK64, inc >> 64, inc & _MASK64], dtype=np.uint64)


def set_pcg64_words(rng: np.random.Generator, words: np.ndarray) -> None:
    """Put :func:`pcg64_words`' (advanced) state back into ``rng``."""
    s = dict(rng.bit_generator.state)
    hi, lo, inc_hi, inc_lo = (int(v) for v in words)
    s["state"] = {"state": (hi << 64) | lo, "inc": (inc_hi << 64) | inc_lo}
    rng.bit_generator.state = s
