"""Branch-free double-precision ``exp``, ``sin``/``cos``/``sincos`` and ``atan2`` for numba.

Why: numba lowers ``math.exp``/``sin``/``atan2`` to libm calls, and LLVM can only vectorise a loop
that calls them when a vector math library (Intel SVML) is linked in; PyPI's llvmlite has none.
These functions are pure arithmetic (multiply, fused multiply-add, add, divide, comparisons turned
into selects, and a couple of integer bit operations through ``bitcast``), so a loop over a batch of
ships that calls them vectorises (AVX2/AVX-512) like any other arithmetic loop; in scalar code they
are about as fast as glibc's (latency on the development machine: sincos 14 ns vs 2 x ~20 ns, atan2
23 vs 22 ns, exp 17 vs 11 ns) and in a vectorised loop 1-2 ns per value. They are written for a
short dependency chain (Estrin's scheme, no table lookups), because a single simulation is
latency-bound.

Algorithms (range reduction + published minimax/rational approximants):

* ``exp``: x = n ln2 + g with Cephes' two-part ln2 (Cody-Waite; Cephes ``exp.c``, S. L. Moshier,
  1989, *Methods and Programs for Mathematical Functions*, Prentice-Hall), e^g = 1 + g + g^2 u(g)
  with the degree-10 minimax polynomial u of SLEEF's ``xexp`` (N. Shibata, F. Petrogalli, 2020,
  "SLEEF: A Portable Vectorized Library of C Standard Mathematical Functions", IEEE TPDS 31(6),
  1316-1327), evaluated by Estrin's scheme; 2^n is built from the exponent bits, in two halves so
  that subnormal results are rounded once (SLEEF's ``ldexp2k``).
* ``sin``/``cos``: Cephes ``sin.c`` polynomials on [-pi/4, pi/4] (Estrin's scheme); the reduction by
  pi/2 is Cody-Waite with fused multiply-adds (as SLEEF's FMA code paths do): x - q pi/2 with pi/2
  in three parts, the first step exact, accurate for |x| < 1e14 (``TRIG_MAX``). Beyond that
  (Payne-Hanek territory) the functions return NaN rather than a wrong number; the simulator's
  angles are below 1e4 rad.
* ``atan2``: Cephes ``atan.c`` rational approximant (degree 4/5 in t^2 on |t| <= 0.66), with the
  octant reduction done on (|y|, |x|) by selects: t = min/max, and (lo - hi)/(lo + hi) above 0.66
  (one division), then pi/4, pi/2, 3pi/4, pi added as double-double constants. Signed zeros,
  infinities and NaN follow C99 Annex F (what ``math.atan2`` does).

Accuracy (``tests/sim/test_sim_speed_equivalence.py`` checks it against ``math`` on 1e5 random
arguments per function over wide ranges and on edge cases; 1e6 samples give the same): exp within 1
ulp (incl. the subnormal range), sin/cos within 2 ulp on |x| < 1e14 (absolute 2.2e-16 near their
zeros), atan2 within 1 ulp.

All functions are ``inline='always'`` numba functions with ``error_model='numpy'``: inside a
compiled loop they are inlined into the caller's IR, so the caller's flags apply. Do not compile
callers with the ``reassoc``/``nnan``/``ninf``/``nsz`` fast-math flags: the Cody-Waite reduction,
the round-to-integer trick and the special-value selects rely on IEEE semantics (``contract``, i.e.
FMA formation, is fine). numba's on-disk cache of a function that inlines these does not notice an
edit of this file (``study.sim.core`` keys its cache on this file's contents; for other cached
callers, clear their ``__pycache__/*.nbi``).
"""
from __future__ import annotations

import math

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["exp", "sin", "cos", "sincos", "atan2", "sqrt", "select", "fma", "TRIG_MAX"]


@intrinsic
def _f64_bits(typingctx, x):
    """Reinterpret a float64 as int64 (no conversion)."""
    if not isinstance(x, types.Float):
        return None
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return sig, codegen


@intrinsic
def _bits_f64(typingctx, i):
    """Reinterpret an int64 as float64 (no conversion)."""
    if not isinstance(i, types.Integer):
        return None
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


@intrinsic
def select(typingctx, cond, a, b):
    """``a if cond else b`` as one LLVM ``select`` instruction (both operands are evaluated).

    A Python conditional expression becomes three basic blocks and a phi in numba's IR; LLVM usually
    turns them back into a select, but numba's SSA and inlining passes pay for every block (compile
    time), and a select cannot be turned into a branch that stops vectorisation. Operands are
    float64.
    """
    if not isinstance(cond, types.Boolean):
        return None
    sig = types.float64(cond, a, b)

    def codegen(context, builder, signature, args):
        c = context.cast(builder, args[0], signature.args[0], types.boolean)
        x = context.cast(builder, args[1], signature.args[1], types.float64)
        y = context.cast(builder, args[2], signature.args[2], types.float64)
        return builder.select(c, x, y)

    return sig, codegen


@intrinsic
def sqrt(typingctx, x):
    """IEEE square root as the ``llvm.sqrt`` intrinsic (one instruction, vectorisable; NaN for x <
    0).

    ``math.sqrt`` becomes a libm call (it may set errno) unless LLVM can prove the argument
    non-negative, and such a call stops a loop from vectorising.
    """
    if not isinstance(x, types.Float):
        return None
    sig = types.float64(types.float64)

    def codegen(context, builder, signature, args):
        arg = context.cast(builder, args[0], signature.args[0], types.float64)
        fn = builder.module.declare_intrinsic("llvm.sqrt", [ir.DoubleType()])
        return builder.call(fn, [arg])

    return sig, codegen


@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c rounded once (the ``llvm.fma`` intrinsic: one instruction on CPUs with FMA, e.g.
    any x86-64 with AVX2; elsewhere LLVM calls libm's exact ``fma``). The trig reduction below
    relies on it."""
    if not all(isinstance(t, types.Float) for t in (a, b, c)):
        return None
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        vals = [context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args)]
        return builder.call(fn, vals)

    return sig, codegen


_JIT = dict(cache=True, inline="always", error_model="numpy")

# round-to-nearest-integer by adding and subtracting 1.5 * 2^52 (exact for |t| < 2^51); the low bits of
# t + MAGIC then hold round(t) as a two's-complement integer
_MAGIC = 6755399441055744.0
_MAGIC_BITS = 0x4338000000000000

# ---------------------------------------------------------------------------------------------------- exp
# x = n ln2 + s, |s| <= ln2/2 (Cody-Waite, Cephes' two-part ln2); e^s = 1 + s + s^2 u(s) with SLEEF's
# minimax polynomial u of degree 10 (xexp, 1-ulp version), by Estrin's scheme: no division and no table
# (a table read on the dependency chain made the speed depend on where the code landed in memory).
_LOG2E = 1.4426950408889634
_LN2_C1 = 6.93145751953125e-1  # ln2 = C1 + C2, C1 with 20 significant bits (n C1 is exact)
_LN2_C2 = 1.42860682030941723212e-6
_EXP_C9 = 2.08860621107283687536341e-09
_EXP_C8 = 2.51112930892876518610661e-08
_EXP_C7 = 2.75573911234900471893338e-07
_EXP_C6 = 2.75572362911928827629423e-06
_EXP_C5 = 2.4801587159235472998791e-05
_EXP_C4 = 0.000198412698960509205564975
_EXP_C3 = 0.00138888888889774492207962
_EXP_C2 = 0.00833333333331652721664984
_EXP_C1 = 0.0416666666666665047591422
_EXP_C0 = 0.166666666666666851703837


@njit(**_JIT)
def exp(x):
    """e**x, branch-free; overflow -> inf, underflow -> 0 (subnormal results rounded once)."""
    # no clamping of x on the way in (it would lengthen the dependency chain): outside [-745.2, 709.8]
    # (where the result is 0 or inf) and for NaN, n and the bit tricks below give garbage, replaced at the end
    tm = x * _LOG2E + _MAGIC
    n = tm - _MAGIC
    ni = _f64_bits(tm) - _MAGIC_BITS
    g = x - n * _LN2_C1
    g = g - n * _LN2_C2
    g2 = g * g
    g4 = g2 * g2
    g8 = g4 * g4
    u = ((_EXP_C9 * g + _EXP_C8) * g8
         + (((_EXP_C7 * g + _EXP_C6) * g2 + (_EXP_C5 * g + _EXP_C4)) * g4
            + ((_EXP_C3 * g + _EXP_C2) * g2 + (_EXP_C1 * g + _EXP_C0))))
    u = u * g + 0.5
    e = 1.0 + (g + g2 * u)
    n1 = ni >> 1  # 2^n in two halves: a subnormal result is rounded once
    n2 = ni - n1
    e = e * _bits_f64((n1 + 1023) << 52)
    e = e * _bits_f64((n2 + 1023) << 52)
    e = select(x > -745.2, e, 0.0)  # below: underflow to 0
    e = select(x < 709.8, e, math.inf)  # above: overflow (between 709.78 and 709.8 the product overflows)
    return select(x == x, e, x)  # NaN in, NaN out


# ---------------------------------------------------------------------------------------------- sin/cos
TRIG_MAX = 1e14
_TWO_OVER_PI = 0.6366197723675814
# pi/2 = P1 + P2 + P3 (+ 5.6e-50), each the double nearest to what is left
_PIO2_P1 = 1.5707963267948966
_PIO2_P2 = 6.123233995736766e-17
_PIO2_P3 = -1.4973849048591698e-33
_SIN0 = 1.58962301576546568060e-10
_SIN1 = -2.50507477628578072866e-8
_SIN2 = 2.75573136213857245213e-6
_SIN3 = -1.98412698295895385996e-4
_SIN4 = 8.33333333332211858878e-3
_SIN5 = -1.66666666666666307295e-1
_COS0 = -1.13585365213876817300e-11
_COS1 = 2.08757008419747316778e-9
_COS2 = -2.75573141792967388112e-7
_COS3 = 2.48015872888517045348e-5
_COS4 = -1.38888888888730564116e-3
_COS5 = 4.16666666666665929218e-2
_TINY_ANGLE = 7.450580596923828e-09  # 2^-27: sin x rounds to x and cos x to 1 below this


@njit(**_JIT)
def sincos(x):
    """(sin x, cos x) with one shared reduction; NaN for non-finite x and for |x| >= TRIG_MAX."""
    ax = abs(x)
    ok = ax < TRIG_MAX  # False for inf and NaN as well
    # q = round(x 2/pi) (add-subtract 1.5 * 2^52; |q| < 2^46 here); r = x - q pi/2 with fused multiply-adds:
    # x - q P1 is exact (the product is exact inside the fma and the difference, below 2 in magnitude, is a
    # multiple of 2^-52), and the next two terms add pi/2's remaining bits (error ~ |q| 2^-160)
    tm = x * _TWO_OVER_PI + _MAGIC
    q = tm - _MAGIC
    quad = (_f64_bits(tm) - _MAGIC_BITS) & 3
    r = fma(-q, _PIO2_P1, x)
    r = fma(-q, _PIO2_P2, r)
    r = fma(-q, _PIO2_P3, r)
    # Cephes sin.c / cos.c polynomials on [-pi/4, pi/4], by Estrin's scheme
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    ps = (_SIN0 * z + _SIN1) * z4 + ((_SIN2 * z + _SIN3) * z2 + (_SIN4 * z + _SIN5))
    pc = (_COS0 * z + _COS1) * z4 + ((_COS2 * z + _COS3) * z2 + (_COS4 * z + _COS5))
    s = r + (r * z) * ps
    c = (1.0 - 0.5 * z) + z2 * pc
    # quadrant: 0 (s, c), 1 (c, -s), 2 (-s, -c), 3 (-c, s)
    sw = (quad & 1) != 0
    so = select(sw, c, s)
    co = select(sw, s, c)
    so = select((quad & 2) != 0, -so, so)
    co = select(((quad + 1) & 2) != 0, -co, co)
    tiny = ax < _TINY_ANGLE  # also keeps the sign of -0.0 and subnormals exact
    so = select(tiny, x, so)
    co = select(tiny, 1.0, co)
    return select(ok, so, math.nan), select(ok, co, math.nan)


@njit(**_JIT)
def sin(x):
    """sin x (see ``sincos``)."""
    return sincos(x)[0]


@njit(**_JIT)
def cos(x):
    """cos x (see ``sincos``)."""
    return sincos(x)[1]


# ------------------------------------------------------------------------------------------------ atan2
_ATAN_P0 = -8.750608600031904122785e-1
_ATAN_P1 = -1.615753718733365076637e1
_ATAN_P2 = -7.500855792314704667340e1
_ATAN_P3 = -1.228866684490136173410e2
_ATAN_P4 = -6.485021904942025371773e1
_ATAN_Q0 = 2.485846490142306297962e1
_ATAN_Q1 = 1.650270098316988542046e2
_ATAN_Q2 = 4.328810604912902668951e2
_ATAN_Q3 = 4.853903996359136964868e2
_ATAN_Q4 = 1.945506571482613964425e2
# multiples of pi/4 as double-double (hi + lo)
_PIO4_HI, _PIO4_LO = 0.7853981633974483, 3.061616997868383e-17
_PIO2_HI, _PIO2_LO = 1.5707963267948966, 6.123233995736766e-17
_3PIO4_HI, _3PIO4_LO = 2.356194490192345, 9.184850993605148e-17
_PI_HI, _PI_LO = 3.141592653589793, 1.2246467991473532e-16


@njit(**_JIT)
def atan2(y, x):
    """atan2(y, x) in [-pi, pi] (Cephes atan.c core, octant reduction by selects)."""
    ay = abs(y)
    ax = abs(x)
    swap = ay > ax  # work with t = lo/hi in [0, 1]; atan(hi/lo) = pi/2 - atan(lo/hi)
    lo = select(swap, ax, ay)
    hi = select(swap, ay, ax)
    both_inf = (ax == math.inf) & (ay == math.inf)
    # atan t = pi/4 + atan((t - 1)/(t + 1)) for t in (0.66, 1]; lo / 0.66 rather than 0.66 hi, which would
    # round when hi is subnormal (near t = 0.66 either formula is accurate, exactly at t = 1 it must be this)
    mid = (lo * 1.5151515151515151 > hi) | both_inf
    # lo + hi overflows for hi > ~9e307: then halves (exact; such numbers are not subnormal)
    big = hi > 1e300
    num = select(mid, select(big, 0.5 * lo - 0.5 * hi, lo - hi), lo)
    den = select(mid, select(big, 0.5 * lo + 0.5 * hi, lo + hi), hi)
    num = select(both_inf, 0.0, num)
    den = select(both_inf | (hi == 0.0), 1.0, den)
    t = num / den
    # a = t + t z P(z) / Q(z), z = t^2 (Cephes atan.c), P and Q by Estrin's scheme (shorter chain)
    z = t * t
    z2 = z * z
    z4 = z2 * z2
    p = _ATAN_P0 * z4 + ((_ATAN_P1 * z + _ATAN_P2) * z2 + (_ATAN_P3 * z + _ATAN_P4))
    q = (z + _ATAN_Q0) * z4 + ((_ATAN_Q1 * z + _ATAN_Q2) * z2 + (_ATAN_Q3 * z + _ATAN_Q4))
    a = t + t * (z * p / q)
    # result = base + sg * a, base in {0, pi/4, pi/2, 3pi/4, pi} as hi + lo:
    #   no swap: 0 (+a) or pi/4 (+a, mid); swap: pi/2 (-a) or pi/4 (-a, mid);
    #   x < 0 (incl. -0): reflected, pi - base and -sg
    neg = math.copysign(1.0, x) < 0.0
    bh = select(mid, _PIO4_HI, select(swap, _PIO2_HI, 0.0))
    bl = select(mid, _PIO4_LO, select(swap, _PIO2_LO, 0.0))
    sg = select(swap, -1.0, 1.0)
    bh = select(neg, select(mid, _3PIO4_HI, select(swap, _PIO2_HI, _PI_HI)), bh)
    bl = select(neg, select(mid, _3PIO4_LO, select(swap, _PIO2_LO, _PI_LO)), bl)
    sg = select(neg, -sg, sg)
    r = bh + (bl + sg * a)
    r = math.copysign(r, y)
    return select((x == x) & (y == y), r, x + y)
