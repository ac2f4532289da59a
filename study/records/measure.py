"""Measurement model: turn a clean simulated trajectory into realistic, reproducible measured data.

Processing order in :meth:`MeasurementModel.apply` (each step optional):

1. **sampling** at ``dt`` (exact source samples where the time exists, else linear interpolation);
2. per channel, on the sampled clean signal, the noise scale ``S_c``: the RMS of the signal, except
   for the *offset channels* (``psi``, ``x0``, ``y0`` by default) where it is the RMS of the
   deviation from the mean (the standard deviation). Heading and positions carry arbitrary offsets
   (initial heading, where the origin is) that say nothing about how large the measured variation
   is; the deviation from the mean does not depend on them, so the same noise fraction means the
   same thing for every record;
3. white Gaussian noise with standard deviation ``noise_level * S_c`` (the *relative* model) and/or
   an absolute standard deviation ``noise_sd[c]`` in the channel's own units (the *absolute* model:
   a sensor's accuracy, as the configs of ``conf/noise/`` give it per sensor; both given, the two
   add as independent noises: ``sqrt((noise_level * S_c)^2 + noise_sd^2)``);
4. coloured noise: a first-order Gauss-Markov process (exact discretisation of an Ornstein-Uhlenbeck
   process, AR(1) on a uniform grid) with correlation time ``tau`` and stationary standard deviation
   ``level * S_c``; lag-1 autocorrelation ``exp(-dt / tau)`` (Gelb 1974, *Applied Optimal
   Estimation*, sec. 3.8; Brown & Hwang 2012, *Introduction to Random Signals and Applied Kalman
   Filtering*, 4th ed., sec. 2.9);
5. constant bias per channel;
6. outliers: with probability ``prob`` per sample and channel, a spike of ``size`` times the
   channel's white noise sigma (``scale='sigma'``, default) or times ``S_c`` (``scale='rms'``) with
   a random sign;
7. dropouts: samples (whole rows) removed, independently with probability ``prob`` or in bursts with
   mean length ``burst`` samples (two-state Markov / Gilbert-Elliott loss model with stationary loss
   fraction ``prob``; Gilbert 1960, Bell Syst. Tech. J. 39(5)). Rows are removed, never set to NaN
   (the record schema forbids NaN).

Random streams: every stream is a child of ``np.random.SeedSequence(seed)`` with a spawn key made
from the channel *name* (CRC-32) and the process (white, coloured, outliers), the same mechanism as
``SeedSequence.spawn`` but keyed by name rather than by position, so adding, removing or reordering
channels never changes another channel's noise, and switching on outliers never changes the white
noise. Dropouts have their own stream.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

DEFAULT_CHANNELS = ("u", "v", "r", "psi", "x0", "y0", "delta")
#: the sensors of an absolute noise config (``conf/noise/*.yaml``, ``kind: absolute``): the key's unit, the
#: factor to the schema's SI/radian units, and the channels the sensor measures
SENSORS = {
    "position_m": ("m", 1.0, ("x0", "y0")),                        # GNSS / optical tracking, per axis
    "heading_deg": ("deg", math.pi / 180.0, ("psi",)),             # gyrocompass / heading sensor
    "yaw_rate_deg_s": ("deg/s", math.pi / 180.0, ("r",)),          # rate-of-turn sensor
    "speed_m_s": ("m/s", 1.0, ("u", "v")),                         # speed log (or GNSS velocity), per axis
    "rudder_deg": ("deg", math.pi / 180.0, ("delta",)),            # rudder angle indicator
}
NOISE_KINDS = ("relative", "absolute")


def sensor_sd(sensors: dict, where: str = "noise") -> dict:
    """Channel -> absolute standard deviation in SI units and radians, from ``{sensor key: sd}``
    in the keys' units (:data:`SENSORS`); an unknown key or a negative value is an error naming
    it."""
    out = {}
    for key, val in (sensors or {}).items():
        if key not in SENSORS:
            raise ValueError(f"{where}: unknown sensor '{key}'; known: {list(SENSORS)} (units in the names)")
        v = float(val)
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"{where}.{key}={val}: a standard deviation must be finite and >= 0")
        _, factor, chans = SENSORS[key]
        out.update({c: v * factor for c in chans})
    return out
OFFSET_CHANNELS = ("psi", "x0", "y0")
_PROCESSES = {"white": 0, "colored": 1, "outliers": 2}


def _stream(seed: int, name: str, process: str | None = None) -> np.random.Generator:
    """Generator for (channel name, process): a SeedSequence child keyed by name, see the module
    docstring."""
    root = np.random.SeedSequence(seed)
    key = (zlib.crc32(name.encode("utf-8")),) + (() if process is None else (_PROCESSES[process],))
    return np.random.default_rng(np.random.SeedSequence(root.entropy, spawn_key=key))


def resample(df: pd.DataFrame, dt: float | None) -> pd.DataFrame:
    """Sample a record at ``t0, t0 + dt, ...`` (up to the last time).

    Rows whose time matches a sample time (to 1e-9 relative) are taken exactly, the others linearly
    interpolated (numeric columns; other columns take the previous row). ``dt=None`` returns a copy.

    Raises
    ------
    ValueError
        ``dt`` not positive, or finer than the record's step (that would invent data).
    """
    out = df.reset_index(drop=True).copy()
    if dt is None:
        return out
    dt = float(dt)
    t = out["time"].to_numpy(float)
    if not dt > 0:
        raise ValueError(f"measurement dt must be positive, got {dt}")
    step = float(np.median(np.diff(t)))
    if dt < step * (1 - 1e-6):
        raise ValueError(f"measurement dt={dt} s is finer than the record's step {step:g} s; "
                         "sample at the record's step or coarser")
    span = t[-1] - t[0]
    n = int(math.floor(span / dt * (1 + 1e-12) + 1e-9)) + 1
    tn = t[0] + np.arange(n) * dt
    idx = np.clip(np.searchsorted(t, tn), 0, len(t) - 1)
    # nearest source sample on either side, to recognise exact matches despite rounding in t0 + k dt
    prev = np.clip(idx - 1, 0, len(t) - 1)
    near = np.where(np.abs(t[prev] - tn) < np.abs(t[idx] - tn), prev, idx)
    exact = np.abs(t[near] - tn) <= 1e-9 * np.maximum(1.0, np.abs(tn))
    cols = {}
    for col in out.columns:
        a = out[col].to_numpy()
        if col == "time":
            cols[col] = np.where(exact, t[near], tn)
        elif np.issubdtype(a.dtype, np.number):
            a = a.astype(float)
            cols[col] = np.where(exact, a[near], np.interp(tn, t, a))
        else:
            cols[col] = a[np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 1)]
    return pd.DataFrame(cols)


def _gauss_markov(rng: np.random.Generator, time: np.ndarray, tau: float, sigma: float) -> np.ndarray:
    """Stationary first-order Gauss-Markov noise at the given (possibly non-uniform) times."""
    n = len(time)
    w = rng.standard_normal(n)
    if n == 0:
        return w
    dts = np.diff(time)
    phi = np.exp(-dts / tau)
    q = np.sqrt(1.0 - phi ** 2)
    if np.allclose(dts, dts[0] if dts.size else 0.0, rtol=1e-9, atol=0.0):
        from scipy.signal import lfilter

        # uniform grid: AR(1) e_k = phi e_{k-1} + q w_k with e_0 drawn from the stationary law
        p, qq = (float(phi[0]), float(q[0])) if dts.size else (0.0, 1.0)
        x = w.copy()
        x[1:] *= qq
        return sigma * lfilter([1.0], [1.0, -p], x)
    e = np.empty(n)
    e[0] = w[0]
    for k in range(1, n):
        e[k] = phi[k - 1] * e[k - 1] + q[k - 1] * w[k]
    return sigma * e


def _per_channel(value, channels, what: str) -> dict:
    """A float for every channel, or a dict channel -> float (missing channels get 0)."""
    if value is None:
        return {c: 0.0 for c in channels}
    if isinstance(value, dict):
        unknown = [k for k in value if k not in channels]
        if unknown:
            raise ValueError(f"{what}: channel(s) {unknown} are not among the measured channels {list(channels)}")
        out = {c: float(value.get(c, 0.0)) for c in channels}
    else:
        out = {c: float(value) for c in channels}
    bad = [c for c, v in out.items() if not (v >= 0 and math.isfinite(v))]
    if bad:
        raise ValueError(f"{what}: must be finite and >= 0 (channel(s) {bad})")
    return out


@dataclass
class MeasurementModel:
    """Seeded measurement model; see the module docstring for the processing and the noise
    definitions.

    Parameters
    ----------
    dt : float or None
        Sample interval [s]; ``None`` keeps the record's own time stamps. Must not be finer than the
        record.
    channels : tuple of str
        Columns that receive noise, bias and outliers (default ``u, v, r, psi, x0, y0, delta``).
        Other columns (``n``, ...) are only sampled.
    noise_level : float or dict
        White-noise standard deviation as a fraction of each channel's scale ``S_c`` (RMS; RMS of
        the deviation from the mean for ``offset_channels``). A dict gives it per channel (absent
        channels: 0).
    noise_sd : dict or None
        Absolute white-noise standard deviation per channel, in the channel's units (m, m/s, rad,
        rad/s); absent channels: 0. ``study.run.pipeline.measurement`` fills it from a noise config
        of ``kind: absolute``.
    bias : dict
        Channel -> constant added, in the channel's units (SI, rad).
    colored : dict or None
        ``{'tau': s, 'level': fraction}`` (``level`` a float or a dict per channel): Gauss-Markov
        noise with correlation time ``tau`` and standard deviation ``level * S_c``.
    outliers : dict or None
        ``{'prob': p, 'size': k, 'scale': 'sigma' | 'rms', 'channels': [...]}``; a spike of ``k``
        white-noise sigmas (default; channels without white noise then get no spikes) or ``k *
        S_c``.
    dropouts : dict or None
        ``{'prob': p}`` (independent losses) plus optionally ``'burst'`` (mean burst length in
        samples, >= 1) or ``'burst_s'`` (in seconds). Lost rows are removed.
    seed : int
        Seed of every random stream.
    offset_channels : tuple of str
        Channels whose scale is the RMS of the deviation from the mean.
    """

    dt: float | None = None
    channels: tuple = DEFAULT_CHANNELS
    noise_level: float | dict = 0.0
    noise_sd: dict | None = None
    bias: dict = field(default_factory=dict)
    colored: dict | None = None
    outliers: dict | None = None
    dropouts: dict | None = None
    seed: int = 0
    offset_channels: tuple = OFFSET_CHANNELS

    def scales(self, sampled: pd.DataFrame) -> dict:
        """The noise scale ``S_c`` of every channel on a sampled clean record."""
        out = {}
        for c in self.channels:
            a = sampled[c].to_numpy(float)
            if c in self.offset_channels:
                a = a - a.mean()
            out[c] = float(np.sqrt(np.mean(a ** 2)))
        return out

    def apply(self, df: pd.DataFrame) -> pd.DataFrame:
        """Return the measured version of the clean record ``df`` (a new frame; ``df`` is not
        modified).

        Raises
        ------
        ValueError
            Missing ``time`` or channel columns, NaN in a channel, or invalid options.
        """
        chans = tuple(self.channels)
        missing = [c for c in ("time",) + chans if c not in df.columns]
        if missing:
            raise ValueError(f"MeasurementModel.apply: the record lacks column(s) {missing}")
        if len(df) < 2:
            raise ValueError("MeasurementModel.apply: the record needs at least 2 samples")
        if np.any(np.diff(df["time"].to_numpy(float)) <= 0):
            raise ValueError("MeasurementModel.apply: 'time' must be strictly increasing")
        out = resample(df, self.dt)
        n = len(out)
        time = out["time"].to_numpy(float)
        if not np.all(np.isfinite(out[list(chans)].to_numpy(float))):
            raise ValueError("MeasurementModel.apply: the clean record has NaN/inf in a measured channel")
        S = self.scales(out)
        white = _per_channel(self.noise_level, chans, "noise_level")
        absolute = _per_channel(self.noise_sd or {}, chans, "noise_sd")
        # the relative and the absolute noise are independent: their standard deviations add in quadrature (a
        # channel with one of them keeps it bit for bit)
        sigma = {c: (math.hypot(white[c] * S[c], absolute[c]) if absolute[c] > 0 else white[c] * S[c])
                 for c in chans}
        col = dict(self.colored or {})
        if col:
            if "tau" not in col or not float(col["tau"]) > 0:
                raise ValueError(f"colored: needs a positive correlation time 'tau' [s], got {col}")
            col_level = _per_channel(col.get("level", 0.0), chans, "colored.level")
        bias = dict(self.bias or {})
        unknown = [k for k in bias if k not in chans]
        if unknown:
            raise ValueError(f"bias: channel(s) {unknown} are not among the measured channels {list(chans)}")
        outl = dict(self.outliers or {})
        if outl:
            p_out = float(outl.get("prob", 0.0))
            size = float(outl.get("size", 0.0))
            scale = outl.get("scale", "sigma")
            if not 0 <= p_out <= 1 or size < 0 or scale not in ("sigma", "rms"):
                raise ValueError(f"outliers: need 0 <= prob <= 1, size >= 0, scale 'sigma' or 'rms'; got {outl}")
            out_chans = tuple(outl.get("channels") or chans)
            if any(c not in chans for c in out_chans):
                raise ValueError(f"outliers.channels {list(out_chans)} must be among {list(chans)}")
            if scale == "sigma" and p_out > 0 and size > 0 and all(sigma[c] == 0 for c in out_chans):
                raise ValueError("outliers: size is in white-noise sigmas but the white noise is 0 on every "
                                 "channel; give scale='rms' or a noise_level")

        for c in chans:
            a = out[c].to_numpy(float).copy()
            changed = False
            if sigma[c] > 0:
                a += sigma[c] * _stream(self.seed, c, "white").standard_normal(n)
                changed = True
            if col and col_level[c] > 0:
                a += _gauss_markov(_stream(self.seed, c, "colored"), time, float(col["tau"]), col_level[c] * S[c])
                changed = True
            if c in bias and bias[c] != 0:
                a += float(bias[c])
                changed = True
            if outl and c in out_chans and p_out > 0:
                rng = _stream(self.seed, c, "outliers")
                hit = rng.random(n) < p_out
                sgn = np.where(rng.random(n) < 0.5, -1.0, 1.0)
                mag = size * (sigma[c] if scale == "sigma" else S[c])
                a += np.where(hit, sgn * mag, 0.0)
                changed = True
            if changed:  # leave untouched channels bit-identical
                out[c] = a

        if self.dropouts:
            keep = self._keep_mask(n, time)
            out = out.loc[keep].reset_index(drop=True)
        return out

    def _keep_mask(self, n: int, time: np.ndarray) -> np.ndarray:
        d = dict(self.dropouts)
        p = float(d.get("prob", 0.0))
        if not 0 <= p < 1:
            raise ValueError(f"dropouts: prob must be in [0, 1), got {p}")
        rng = _stream(self.seed, "__dropouts__")
        burst = d.get("burst")
        if d.get("burst_s") is not None:
            step = float(np.median(np.diff(time))) if n > 1 else 1.0
            burst = float(d["burst_s"]) / step
        if p == 0:
            return np.ones(n, dtype=bool)
        if burst is None:
            return rng.random(n) >= p
        b = float(burst)
        # Gilbert chain: leave a loss with prob 1/b (mean burst b); enter with a so that a/(a + 1/b) = p
        a = p / ((1 - p) * b)
        if b < 1 or a > 1:
            raise ValueError(f"dropouts: burst={b:g} samples is impossible with prob={p} "
                             "(need burst >= 1 and burst >= prob / (1 - prob))")
        u = rng.random(n)
        lost = np.empty(n, dtype=bool)
        lost[0] = u[0] < p  # start in the stationary law
        for k in range(1, n):
            lost[k] = (u[k] >= 1.0 / b) if lost[k - 1] else (u[k] < a)
        return ~lost
