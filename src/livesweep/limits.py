"""Size limits on what a case may ask for, in one place.

Every limit here is generous for flight-test data and far below what would exhaust the machine
livesweep is sized for (2 cores, 24 GB, shared). A number beyond a limit is a typo or a crafted
file, not a test point: the stage that meets it raises a one-line
:class:`~livesweep.errors.ConfigError` naming the file, key and value before allocating anything.

Reference case, which must stay well inside every limit: 1 kHz x 1 hour x 20 signals
(72e6 resampled values, 0.58 GB per float64 copy of the record).

Budget
------
* The resampled record: :data:`MAX_RECORD_VALUES` samples x signals, 1.2 GB per float64 copy;
  the frequency-response stage holds about five copies (values, valid mask, repaired copy,
  spectral rows, wild-point medians), about 6 GB at the limit.
* Spectral arrays: :data:`MAX_SPECTRAL_VALUES` complex values (3.2 GB of complex128) for any one
  of: the transforms of one window length (signals x segments x frequencies), its spectral
  matrix (signals x signals x frequencies), and the composite responses
  (outputs x inputs x n_freq x windows).
* Models: a transfer-function numerator or denominator is of order at most :data:`MAX_TF_ORDER`;
  a state-space model has at most :data:`MAX_MODEL_DIMENSION` states, inputs and outputs.
* The live monitor (``monitor``, ``replay``; its settings from a map, a case, the command line or
  a recording): at most :data:`MAX_MONITOR_PAIRS` pairs, a grid of at most
  :data:`MAX_MONITOR_RATE_HZ`, an estimate at most every
  :data:`MIN_UPDATE_PERIOD_S`, a sliding window of at most :data:`MAX_WINDOW_S` holding at most
  :data:`MAX_RECORD_VALUES` samples x signals, and its segment transforms at most
  :data:`MAX_SPECTRAL_VALUES` values.
* Text: a case file is at most :data:`MAX_CONFIG_BYTES`; a matrix entry of a state-space model at
  most :data:`MAX_EXPRESSION_CHARS` characters, :data:`MAX_EXPRESSION_TOKENS` tokens and
  :data:`MAX_EXPRESSION_DEPTH` levels of parentheses and signs (real entries are a few terms).
"""

from __future__ import annotations

import math

__all__ = [
    "MAX_CONFIG_BYTES", "MAX_SAMPLE_RATE_HZ", "MAX_N_FREQ", "MAX_WINDOWS", "MAX_WINDOW_S",
    "MAX_RECORD_VALUES", "MAX_SPECTRAL_VALUES", "MAX_NAME_CHARS", "MAX_MODEL_DIMENSION",
    "MAX_EXPRESSION_CHARS", "MAX_EXPRESSION_TOKENS", "MAX_EXPRESSION_DEPTH", "MAX_TF_ORDER",
    "MIN_UPDATE_PERIOD_S", "MAX_MONITOR_PAIRS", "MAX_MONITOR_RATE_HZ", "window_spectra_values",
]

#: Largest case file or channel map [bytes] (real ones are a few kB).
MAX_CONFIG_BYTES = 16 * 2**20
#: Highest resampling rate [Hz]: above every flight-data logger (IMU batch sampling is <= 8 kHz).
MAX_SAMPLE_RATE_HZ = 100_000.0
#: Most points of the composite frequency grid (default 150; a few hundred in practice).
MAX_N_FREQ = 10_000
#: Most window lengths in ``windows_s`` (default five).
MAX_WINDOWS = 20
#: Longest spectral window [s] (one day; a window must also fit twice in the record).
MAX_WINDOW_S = 86_400.0
#: Most resampled values, samples x signals, over the concatenated records of a stage.
MAX_RECORD_VALUES = 150_000_000
#: Most complex values in any one spectral array (see the module notes).
MAX_SPECTRAL_VALUES = 200_000_000
#: Longest signal name [characters].
MAX_NAME_CHARS = 64
#: Most states, inputs or outputs of a state-space model (real models: 6 to 40 states).
MAX_MODEL_DIMENSION = 200
#: Longest matrix-entry expression [characters].
MAX_EXPRESSION_CHARS = 2_000
#: Most tokens (numbers, names, operators, parentheses) in a matrix-entry expression.
MAX_EXPRESSION_TOKENS = 400
#: Deepest nesting of parentheses and unary signs in a matrix-entry expression.
MAX_EXPRESSION_DEPTH = 50
#: Shortest update period of the live monitor [s of data] (default 0.2 s; the view refreshes at 1 Hz).
MIN_UPDATE_PERIOD_S = 0.05
#: Most input/output pairs the live monitor analyses (the presets: 9 to 15; each pair costs about
#: 0.1 ms of a core per estimate).
MAX_MONITOR_PAIRS = 200
#: Highest grid rate of the live monitor [Hz]: telemetry streams reach a few hundred Hz (a 400 Hz
#: DataFlash IMU streamed whole); at 100 kHz, replaying 80 s of data took 252 s and 2.8 GB.
MAX_MONITOR_RATE_HZ = 2_000.0
#: Highest order (degree in s) of a transfer-function numerator or denominator (real ones are 0 to 6;
#: at a few hundred the fit's float64 polynomial coefficients overflow and its cost is undefined).
MAX_TF_ORDER = 20


def window_spectra_values(n_signals: int, n_samples: int, sample_rate_hz: float, window_s: float,
                          overlap: float, band_rad_s) -> int:
    """Complex values the transforms of one window length hold (an upper bound).

    Mirrors the spectral stage: windows of ``n = round(window_s * fs)`` samples every
    ``hop = round((1 - overlap) n)`` samples, each transformed to the FFT bins that cover the band
    (:func:`livesweep.spectral.transform.fft_length`, :func:`~livesweep.spectral.transform.bin_grid`).

    Parameters
    ----------
    n_signals : int
        Signals transformed (inputs, outputs and references).
    n_samples : int
        Record length [samples].
    sample_rate_hz : float
        [Hz].
    window_s : float
        Window length [s].
    overlap : float
        Window overlap fraction in [0, 1).
    band_rad_s : (float, float)
        Band [rad/s].

    Returns
    -------
    int
        ``max(signals x segments x frequencies, signals x signals x frequencies)``.
    """
    from livesweep.spectral.transform import bin_grid, fft_length     # the grid the transforms really use

    n = max(1, int(round(window_s * sample_rate_hz)))
    hop = max(1, int(round((1.0 - overlap) * n)))
    segments = max(0, n_samples - n) // hop + 1
    n_fft = fft_length(n)
    try:
        freqs = bin_grid(float(band_rad_s[0]), float(band_rad_s[1]), n_fft, sample_rate_hz)[1].size
    except ValueError:      # a band the spectral stage refuses: bound by the bin spacing
        freqs = max(2, int(math.ceil((band_rad_s[1] - band_rad_s[0]) * n_fft / (2 * math.pi * sample_rate_hz))) + 2)
    return max(n_signals * segments * freqs, n_signals * n_signals * freqs)
