"""``[transfer_functions.<name>]`` tables, parsed: the structure (and band) of a pair's model.

A case file's tables are fitted by ``livesweep identify`` (:mod:`livesweep.stages.parametric`); a
channel map's (or a case used as one) give each test point's model its structure in the live
monitor (:mod:`livesweep.ident.test_point_model`). One parser for both, with errors naming the
file and the key.
"""

from __future__ import annotations

from dataclasses import dataclass

from livesweep.errors import ConfigError, check_band, quote
from livesweep.ident.transfer_function import STRUCTURE_PREFIXES, TransferFunctionModel, parse_structure
from livesweep.settings_schema import require_table

__all__ = ["TransferFunctionSpec", "specs_of_tables"]

#: The keys of a ``[transfer_functions.<name>]`` table.
_TF_KEYS = {"output", "input", "numerator", "denominator", "delay", "band_rad_s"}


def _tf_table(path, name: str, raw) -> dict:
    where = f"{path}: transfer_functions.{name}"
    require_table(raw, _TF_KEYS, where)
    for key in ("output", "input", "denominator"):
        if not isinstance(raw.get(key), str):
            raise ConfigError(f"{where}.{key}: required, a string, got {quote(raw.get(key))}")
    numerator = raw.get("numerator", "")
    if isinstance(numerator, bool) or not isinstance(numerator, (str, int)):
        raise ConfigError(f"{where}.numerator: must be a string (or an order), got {quote(numerator)}")
    if not isinstance(raw.get("delay", True), bool):
        raise ConfigError(f"{where}.delay: must be true or false, got {quote(raw['delay'])}")
    if raw.get("band_rad_s") is not None:
        check_band(raw["band_rad_s"], f"{where}.band_rad_s")
    return raw


@dataclass(frozen=True)
class TransferFunctionSpec:
    """One ``[transfer_functions.<name>]`` table, parsed: the model and its fitting band.

    Attributes
    ----------
    model : TransferFunctionModel
        Name, numerator, denominator, delay, output and input.
    band_rad_s : (float, float) or None
        Fitting band [rad/s]; None: the pair's coherent band.
    """

    model: TransferFunctionModel
    band_rad_s: tuple | None = None


def specs_of_tables(tables, path) -> tuple[TransferFunctionSpec, ...]:
    """The ``[transfer_functions.*]`` tables ``tables`` of the file ``path`` (a case or a map),
    validated and parsed (ConfigError naming file and key)."""
    if not isinstance(tables, dict):
        raise ConfigError(f"{path}: transfer_functions: must be a table of [transfer_functions.NAME] tables, "
                          f"got {quote(tables)}")
    specs = []
    for name, raw in tables.items():
        t = _tf_table(path, name, raw)
        where = f"{path}: transfer_functions.{name}"
        structures = {}
        for key, prefix in STRUCTURE_PREFIXES.items():
            try:
                structures[key] = parse_structure(t.get(key, ""), prefix=prefix)
            except ConfigError as exc:
                raise ConfigError(f"{where}.{key}: {exc}") from None
        try:
            model = TransferFunctionModel(name=name, numerator=structures["numerator"],
                                          denominator=structures["denominator"],
                                          delay=bool(t.get("delay", True)), output=t["output"], input=t["input"])
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        band = check_band(t["band_rad_s"], f"{where}.band_rad_s") if t.get("band_rad_s") is not None else None
        specs.append(TransferFunctionSpec(model, band))
    return tuple(specs)


