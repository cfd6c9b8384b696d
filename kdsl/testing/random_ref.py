"""A NumPy model of kdsl's (and Warp's) random numbers and noise, for references.

Written from the algorithm (docs/random.md), independently of the kdsl code it
checks: a vectorized PCG hash over ``uint32`` arrays, the draws built on it, and
Perlin/curl noise. Integer streams and ``randf`` are exact. Where the kernel
rounds to float32 before a transcendental function (``2*pi*u``, ``u + eps``)
the model rounds the same way, then evaluates the function in float64, so a
float32 kernel stays within a few ulps of it. Noise is evaluated in float64 from
the exact float32 lattice gradients.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

U32 = np.uint32
F32 = np.float32
PI32 = F32(math.pi)
TWO_PI32 = F32(2.0) * PI32
RANDN_EPSILON = F32(5.96e-8)
PRIMES = (73856093, 19349663, 53471161, 10000019)
CURL_OFFSETS = (10019689, 13112221)


def pcg(state: np.ndarray) -> np.ndarray:
    """The PCG hash of each uint32 (Jarzynski and Olano 2020), wrapping mod 2^32."""
    s = np.asarray(state, dtype=U32)
    with np.errstate(over="ignore"):
        b = s * U32(747796405) + U32(2891336453)
        c = ((b >> ((b >> U32(28)) + U32(4))) ^ b) * U32(277803737)
    return (c >> U32(22)) ^ c


def as_u32(x: np.ndarray | int) -> np.ndarray:
    """Signed or unsigned integers reinterpreted as uint32 (two's complement)."""
    return np.asarray(x, dtype=np.int64).astype(np.uint64).astype(U32)


def rand_init(seed: np.ndarray | int, offset: np.ndarray | int | None = None) -> np.ndarray:
    """``rand_init(seed)`` / ``rand_init(seed, offset)`` over arrays."""
    if offset is None:
        return pcg(as_u32(seed))
    with np.errstate(over="ignore"):
        return pcg(as_u32(seed) + pcg(as_u32(offset)))


class Stream:
    """One generator state per element; each draw advances every state once or more."""

    def __init__(self, state: np.ndarray) -> None:
        self.state = np.array(state, dtype=U32)

    def next(self) -> np.ndarray:
        """Advance every state; gives the new states."""
        self.state = pcg(self.state)
        return self.state

    def randu(self, lo=None, hi=None) -> np.ndarray:
        s = self.next()
        if lo is None:
            return s.copy()
        with np.errstate(over="ignore", divide="ignore"):
            span = as_u32(hi) - as_u32(lo)
            rem = np.where(span == 0, U32(0), s % np.where(span == 0, U32(1), span))
            return rem + as_u32(lo)

    def randi(self, lo=None, hi=None) -> np.ndarray:
        return self.randu(lo, hi).view(np.int32)

    def randf(self, lo=None, hi=None) -> np.ndarray:
        u = (self.next() >> U32(8)).astype(F32) * F32(1.0 / 16777216.0)
        if lo is None:
            return u
        lo, hi = np.asarray(lo, F32), np.asarray(hi, F32)
        with np.errstate(over="ignore", invalid="ignore"):
            return ((hi - lo) * u + lo).astype(F32)

    def randn(self) -> np.ndarray:
        u1 = (self.randf() + RANDN_EPSILON).astype(F32)
        theta = (TWO_PI32 * self.randf()).astype(F32)
        r = F32(np.sqrt(F32(-2.0) * F32(np.log(u1.astype(np.float64)))))
        return r.astype(np.float64) * np.cos(theta.astype(np.float64))

    def theta(self) -> np.ndarray:
        """An angle drawn as ``randf(state, 0, 2*pi)`` (float32), as float64."""
        return self.randf(F32(0.0), TWO_PI32).astype(np.float64)

    def sample_triangle(self) -> np.ndarray:
        r = np.sqrt(self.randf().astype(np.float64))
        return np.stack([1.0 - r, self.randf() * r], axis=-1)

    def sample_unit_ring(self) -> np.ndarray:
        t = self.theta()
        return np.stack([np.cos(t), np.sin(t)], axis=-1)

    def sample_unit_disk(self) -> np.ndarray:
        r = np.sqrt(self.randf().astype(np.float64))
        t = self.theta()
        return np.stack([r * np.cos(t), r * np.sin(t)], axis=-1)

    def _sphere(self, hemi: bool, ball: bool) -> np.ndarray:
        u = self.randf()
        arg = (F32(1.0) - u) if hemi else (F32(1.0) - F32(2.0) * u)
        phi = np.arccos(arg.astype(F32).astype(np.float64))
        t = self.theta()
        r = np.cbrt(self.randf().astype(np.float64)) if ball else 1.0
        return np.stack([r * np.cos(t) * np.sin(phi), r * np.sin(t) * np.sin(phi),
                         r * np.cos(phi)], axis=-1)  # fmt: skip

    def sample_unit_sphere_surface(self) -> np.ndarray:
        return self._sphere(False, False)

    def sample_unit_sphere(self) -> np.ndarray:
        return self._sphere(False, True)

    def sample_unit_hemisphere_surface(self) -> np.ndarray:
        return self._sphere(True, False)

    def sample_unit_hemisphere(self) -> np.ndarray:
        return self._sphere(True, True)

    def sample_unit_box(self, n: int) -> np.ndarray:
        """``sample_unit_square``/``cube``/hypercube: ``n`` draws minus 0.5 (exact)."""
        return np.stack([self.randf() - F32(0.5) for _ in range(n)], axis=-1)

    def sample_cdf(self, cdf: np.ndarray) -> np.ndarray:
        u = self.randf()
        if len(cdf) == 0:
            return np.zeros(u.shape, np.int32)
        return np.minimum(np.searchsorted(cdf.astype(F32), u, side="left"), len(cdf) - 1)

    def poisson(self, lam: np.ndarray) -> np.ndarray:
        """Element by element (the draws per element vary), in float32 like the kernel."""
        out = np.zeros(self.state.shape, np.uint32)
        for i in np.ndindex(self.state.shape):
            one = _Scalar(self.state[i])
            out[i] = one.poisson(F32(lam[i]))
            self.state[i] = one.state
        return out


class _Scalar:
    """A single state, for the rejection loops of ``poisson``."""

    def __init__(self, state) -> None:
        self.state = U32(state)

    def randf(self) -> np.float32:
        self.state = pcg(self.state)[()]
        return F32(self.state >> U32(8)) * F32(1.0 / 16777216.0)

    def poisson(self, lam: np.float32) -> int:
        if lam >= F32(10.0):
            return self._ptrs(lam)
        if lam == F32(0.0):
            return 0
        enlam = F32(math.exp(-float(lam)))
        count, prod = 0, F32(1.0)
        while True:
            prod = F32(prod * self.randf())
            if not prod > enlam:
                return count
            count += 1

    def _ptrs(self, lam: np.float32) -> int:
        def log32(x):
            return F32(math.log(float(x)))

        slam, loglam = F32(math.sqrt(float(lam))), log32(lam)
        b = F32(F32(0.931) + F32(2.53) * slam)
        a = F32(F32(-0.059) + F32(0.02483) * b)
        invalpha = F32(F32(1.1239) + F32(1.1328) / F32(b - F32(3.4)))
        vr = F32(F32(0.9277) - F32(3.6224) / F32(b - F32(2.0)))
        while True:
            u = F32(self.randf() - F32(0.5))
            v = self.randf()
            us = F32(F32(0.5) - abs(u))
            k = F32(math.floor(F32(F32(F32(F32(F32(2.0) * a) / us) + b) * u) + lam + F32(0.43)))
            if us >= F32(0.07) and v <= vr:
                return int(k)
            if k < 0 or (us < F32(0.013) and v > us):
                continue
            lhs = F32(F32(log32(v) + log32(invalpha)) - log32(F32(a / F32(us * us)) + b))
            rhs = F32(F32(-lam + F32(k * loglam)) - _loggam32(F32(k + F32(1.0))))
            if lhs <= rhs:
                return int(k)


#: Zhang and Jin's Stirling series coefficients a[0..9] (SPECFUN), as float32.
_LOGGAM_A = [F32(c) for c in (
    8.333333333333333e-02, -2.777777777777778e-03, 7.936507936507937e-04,
    -5.952380952380952e-04, 8.417508417508418e-04, -1.917526917526918e-03,
    6.410256410256410e-03, -2.955065359477124e-02, 1.796443723688307e-01,
    -1.39243221690590e00)]  # fmt: skip


def _loggam32(x: np.float32) -> np.float32:
    """log(Gamma(x)) with float32 rounding at every step, as the kernel computes it."""
    if x in (F32(1.0), F32(2.0)):
        return F32(0.0)
    n = int(F32(F32(7.0) - x)) if x < F32(7.0) else 0
    x0 = F32(x + F32(n))
    x2 = F32(F32(F32(1.0) / x0) * F32(F32(1.0) / x0))
    gl0 = _LOGGAM_A[9]
    for c in reversed(_LOGGAM_A[:9]):
        gl0 = F32(F32(gl0 * x2) + c)
    half_log_2pi = F32(F32(0.5) * F32(1.8378770664093453))
    gl = F32(F32(F32(gl0 / x0) + half_log_2pi) + F32(F32(x0 - F32(0.5)) * F32(math.log(x0))))
    gl = F32(gl - x0)
    for _ in range(n):
        gl = F32(gl - F32(math.log(float(F32(x0 - F32(1.0))))))
        x0 = F32(x0 - F32(1.0))
    return gl


# --- noise ------------------------------------------------------------------------


def _hash(state: np.ndarray, idx: list[np.ndarray]) -> np.ndarray:
    """Warp's lattice hash: ``i0*p0 ^ i1*p1 ^ ... ^ (iN*pN + state)`` in uint32."""
    with np.errstate(over="ignore"):
        terms = [as_u32(i) * U32(p) for i, p in zip(idx, PRIMES)]
        terms[-1] = terms[-1] + np.asarray(state, U32)
    out = terms[0]
    for t in terms[1:]:
        out = out ^ t
    return out


def lattice_gradient(state: np.ndarray, idx: list[np.ndarray]) -> np.ndarray:
    """The unit gradient at lattice points ``idx`` (shape (..., N)); 1-D: a scalar in [-1, 1)."""
    s = Stream(_hash(state, idx))
    n = len(idx)
    if n == 1:
        return (F32(2.0) * s.randf() - F32(1.0)).astype(np.float64)[..., None]
    g = s.sample_unit_box(n).astype(np.float64)
    length = np.sqrt(np.sum(g * g, axis=-1, keepdims=True))
    return np.where(length > 0, g / np.where(length > 0, length, 1.0), 0.0)


def _fade(t):
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _fade_d(t):
    return 30.0 * t * t * (t * (t - 2.0) + 1.0)


def perlin(state, p: np.ndarray, period: np.ndarray | None = None):
    """Value and gradient of Perlin noise at float32 points ``p`` (shape (..., N)).

    ``period`` (shape (N,) or broadcastable ints) wraps the lattice with C's ``%``.
    """
    p = np.asarray(p, F32)
    f = np.floor(p)
    d = (p - f).astype(np.float64)
    lo = f.astype(np.int64).astype(np.int32)
    n = p.shape[-1]

    def corner_index(k, bit):
        i = lo[..., k].astype(np.int64) + bit
        if period is not None:
            i = np.fmod(np.fmod(lo[..., k].astype(np.int64), period[k]) + bit, period[k])
        return i.astype(np.int32)

    values, grads = {}, {}
    for bits in itertools.product((0, 1), repeat=n):
        idx = [corner_index(k, bits[k]) for k in range(n)]
        g = lattice_gradient(state, idx)
        off = d - np.array(bits, np.float64)
        values[bits] = np.sum(off * g, axis=-1)
        grads[bits] = g
    for k in range(n):  # blend x first, as Warp does
        t = d[..., k]
        s, s1 = _fade(t), _fade_d(t)
        e = np.zeros(n)
        e[k] = 1.0
        nv, ng = {}, {}
        for bits in itertools.product((0, 1), repeat=n - k - 1):
            a, b = (0, *bits), (1, *bits)
            va, vb = values[a], values[b]
            nv[bits] = va + (vb - va) * s
            ng[bits] = (grads[a] + (grads[b] - grads[a]) * s[..., None]
                        + ((vb - va) * s1)[..., None] * e)  # fmt: skip
        values, grads = nv, ng
    return values[()], grads[()]


def curlnoise(state, p: np.ndarray, octaves: int, lacunarity: float, gain: float) -> np.ndarray:
    """Warp's curl noise at float32 points ``p`` (2-D: rotated gradient; 3-D/4-D: curl)."""
    p = np.asarray(p, F32)
    n = p.shape[-1]
    fields = 1 if n == 2 else 3
    sums = [np.zeros(p.shape) for _ in range(fields)]
    freq, amp = F32(1.0), F32(1.0)
    state = np.broadcast_to(np.asarray(state, U32), p.shape[:-1]).copy()
    for _ in range(octaves):
        pt = (freq * p).astype(F32)
        for j in range(fields):
            if j:
                with np.errstate(over="ignore"):
                    state = pcg(state + pcg(U32(CURL_OFFSETS[j - 1])))
            sums[j] += float(amp) * perlin(state, pt)[1]
        amp, freq = F32(amp * F32(gain)), F32(freq * F32(lacunarity))
    if n == 2:
        return np.stack([-sums[0][..., 1], sums[0][..., 0]], axis=-1)
    s1, s2, s3 = sums
    return np.stack([s3[..., 1] - s2[..., 2], s1[..., 2] - s3[..., 0], s2[..., 0] - s1[..., 1]],
                    axis=-1)  # fmt: skip
