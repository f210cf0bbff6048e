"""The scan's point cloud (``measurement.triangulation.cloud_points``): rays through the smoothed centres
met with their light planes in one pass, the ray table read where the first ray lookup did not already
read it. The arithmetic of ``rays_at`` and ``intersect`` (``_kernels.rays``), so the points are theirs
to the bit."""

from __future__ import annotations

import llvmlite.ir as ir
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .jit import compiled

_AHEAD = 16  # rays whose table entries are requested ahead of their turn


@intrinsic
def _prefetch(typingctx, flat, at):
    """Ask the CPU to bring row ``at`` of the 2-D array ``flat`` into the cache (LLVM's prefetch: read,
    high locality); no effect on any value. The table lookups miss the cache once per centre and do not
    depend on each other, so asking ahead overlaps their waits."""
    sig = types.void(flat, at)

    def codegen(context, builder, signature, args):
        arrty = signature.args[0]
        ary = context.make_array(arrty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, arrty, ary, [args[1], context.get_constant(types.intp, 0)],
                                       wraparound=False)
        i8p, i32 = ir.IntType(8).as_pointer(), ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0i8")
        builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


@compiled
def _cell(u, w):
    """Left table column (int64) of the interpolation at sub-pixel column u, as ``rays_at`` takes it."""
    return min(max(np.int64(np.floor(u)), 0), w - 2)


@compiled
def rays_and_cells(u, v, flat, w, out, cells):
    """``rays_at`` into ``out`` (M, 3), keeping the two table entries (x, y) each ray interpolated between
    in ``cells`` (M, 2, 2) float32."""
    for i in range(len(u)):
        j = i + _AHEAD
        if j < len(u):
            ahead = np.int64(v[j]) * w + _cell(u[j], w)
            if 0 <= ahead < len(flat):
                _prefetch(flat, ahead)
        u0 = _cell(u[i], w)
        f = u[i] - u0
        g = 1 - f
        at = np.int64(v[i]) * w + u0
        if at < 0 or at + 1 >= len(flat):
            raise IndexError("rays_at: a centre lies outside the ray table")
        x0, y0, x1, y1 = flat[at, 0], flat[at, 1], flat[at + 1, 0], flat[at + 1, 1]
        out[i, 0] = np.float64(x0) * g + np.float64(x1) * f
        out[i, 1] = np.float64(y0) * g + np.float64(y1) * f
        out[i, 2] = 1.0
        cells[i, 0, 0], cells[i, 0, 1], cells[i, 1, 0], cells[i, 1, 1] = x0, y0, x1, y1
    return out


@compiled
def cloud_points(u_new, u, v, idx, labels, cells, flat, w, planes, out):
    """Into ``out`` (K, 3) mm: ``intersect(rays_at(u_new[idx], v[idx]), planes[labels[idx]])`` for the
    centres ``idx`` (K,) whose first rays (at columns ``u``) left their table entries in ``cells``
    (M, 2, 2) (``rays_and_cells``); the table ``flat`` (H * W, 2) is read only where the new column
    interpolates between other entries (a few per cent of the smoothed centres)."""
    for q in range(len(idx)):
        i = idx[q]
        u0 = _cell(u_new[i], w)
        f = u_new[i] - u0
        g = 1 - f
        if u0 == _cell(u[i], w):
            x0, y0 = np.float64(cells[i, 0, 0]), np.float64(cells[i, 0, 1])
            x1, y1 = np.float64(cells[i, 1, 0]), np.float64(cells[i, 1, 1])
        else:
            at = np.int64(v[i]) * w + u0
            x0, y0 = np.float64(flat[at, 0]), np.float64(flat[at, 1])
            x1, y1 = np.float64(flat[at + 1, 0]), np.float64(flat[at + 1, 1])
        r0 = x0 * g + x1 * f
        r1 = y0 * g + y1 * f
        p = planes[labels[i]]
        denom = (r0 * p[0] + 1.0 * p[2]) + r1 * p[1]
        s = p[3] / denom
        if abs(denom) < 1e-9:
            s = np.nan
        out[q, 0] = r0 * s
        out[q, 1] = r1 * s
        out[q, 2] = 1.0 * s
    return out
