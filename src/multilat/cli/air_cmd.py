"""``multilat air``: phase and group index of air and the distance sensitivities (seed 000 Table II)."""

from __future__ import annotations

from typing import Optional

import typer
from rich.table import Table

from multilat import air
from multilat.cli.app import app, console, emit_json
from multilat.errors import MultilatError

DEFAULT_HUMIDITY_PCT = 50.0

SIGN_CONVENTION = ("s_X = (1/n_g) dn_g/dX: change of a reported distance, in um/m, when the air "
                   "parameter rises by one unit and the index is not updated; a sensor reading one "
                   "unit too high makes distances -s_X um/m too long (docs/air.md)")


@app.command("air")
def air_command(
    temperature_c: float = typer.Option(20.0, "--temperature-c", help="Air temperature, °C."),
    pressure_hpa: float = typer.Option(1013.25, "--pressure-hpa", help="Air pressure, hPa."),
    humidity_pct: Optional[float] = typer.Option(
        None, "--humidity-pct",
        help=f"Relative humidity, % (default {DEFAULT_HUMIDITY_PCT:g} unless --dew-point-c or "
             "--water-vapour-pa is given)."),
    dew_point_c: Optional[float] = typer.Option(None, "--dew-point-c",
                                                help="Dew point, °C (instead of --humidity-pct)."),
    water_vapour_pa: Optional[float] = typer.Option(
        None, "--water-vapour-pa", help="Water-vapour partial pressure, Pa (instead of --humidity-pct)."),
    co2_ppm: float = typer.Option(450.0, "--co2-ppm", help="CO2 content, µmol/mol (ppm)."),
    wavelength_nm: float = typer.Option(1550.0, "--wavelength-nm", help="Vacuum wavelength, nm (default: "
                                        "the --instrument's, else 1550)."),
    instrument: Optional[str] = typer.Option(None, "--instrument",
                                             help="Instrument preset or TOML: its ADM's vacuum wavelength "
                                                  "(adm.wavelength_nm), as budget and correct use it."),
    formula: str = typer.Option("ciddor", "--formula",
                                help="ciddor (Ciddor 1996), edlen (Bönsch & Potulski 1998) or "
                                     "edlen-nist (NIST modified Edlén; CO2 fixed at 450 ppm)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
) -> None:
    """Phase and group refractive index of air, and the relative distance sensitivity (µm/m per
    °C, hPa, %RH, ppm CO2; group index, seed paper Table II sign convention)."""
    wavelength_nm = _wavelength_nm(wavelength_nm, instrument)
    n_given = sum(v is not None for v in (humidity_pct, dew_point_c, water_vapour_pa))
    if n_given > 1:
        raise MultilatError("give only one of --humidity-pct, --dew-point-c, --water-vapour-pa")
    if n_given == 0:
        humidity_pct = DEFAULT_HUMIDITY_PCT
    kw = dict(humidity_pct=humidity_pct, dew_point_c=dew_point_c, water_vapour_pa=water_vapour_pa,
              co2_ppm=co2_ppm, wavelength_m=wavelength_nm * 1e-9, formula=formula)
    # hPa -> Pa at the edge (validation and its message happen in the library)
    if pressure_hpa != pressure_hpa or pressure_hpa < 0:
        raise MultilatError(f"pressure_hpa must be a finite number >= 0, got {pressure_hpa!r}")
    p_pa = pressure_hpa * 100.0
    n = float(air.phase_index(temperature_c, p_pa, **kw))
    ng = float(air.group_index(temperature_c, p_pa, **kw))
    sens = {k: float(v) * 1e6 for k, v in air.sensitivities(temperature_c, p_pa, **kw).items()}

    if as_json:
        emit_json(command="air", obj={
            "formula": formula,
            "inputs": {"temperature_c": temperature_c, "pressure_hpa": pressure_hpa,
                       "humidity_pct": humidity_pct, "dew_point_c": dew_point_c,
                       "water_vapour_pa": water_vapour_pa, "co2_ppm": co2_ppm,
                       "wavelength_nm": wavelength_nm, "instrument": instrument},
            "phase_index": n,
            "group_index": ng,
            "sensitivity_um_per_m": sens,
            "sensitivity_units": {k: f"um/m per {u}" for k, u in air.SENSITIVITY_UNITS.items()},
            "sign_convention": SIGN_CONVENTION,
        })
        return

    hum = (f"{humidity_pct:g} %RH" if humidity_pct is not None else
           f"dew point {dew_point_c:g} °C" if dew_point_c is not None else f"p_w {water_vapour_pa:g} Pa")
    console.print(f"air: {formula}, {temperature_c:g} °C, {pressure_hpa:g} hPa, {hum}, "
                  f"{co2_ppm:g} ppm CO2, λ = {wavelength_nm:g} nm (vacuum)")
    console.print(f"  phase index n   = {n:.10f}")
    console.print(f"  group index n_g = {ng:.10f}")
    t = Table(title="distance sensitivity (group index)", title_justify="left")
    t.add_column("parameter")
    t.add_column("µm/m per unit", justify="right")
    t.add_column("as in Table II", justify="right")
    t.add_row("temperature", f"{sens['temperature_c']:+.4f} /°C", f"{sens['temperature_c']:+.2f} /°C")
    t.add_row("pressure", f"{sens['pressure_hpa']:+.4f} /hPa", f"{sens['pressure_hpa']:+.2f} /hPa")
    t.add_row("humidity", f"{sens['humidity_pct']:+.5f} /%RH",
              f"{10 * sens['humidity_pct']:+.2f} for +10 %")
    t.add_row("CO2", f"{sens['co2_ppm']:+.6f} /ppm", f"{200 * sens['co2_ppm']:+.2f} for +200 ppm")
    console.print(t)
    console.print("sign: the change of a reported distance when the air parameter rises by one unit "
                  "and the index is not updated (a sensor reading high gives the opposite sign).")


def _wavelength_nm(wavelength_nm: float, instrument: str | None) -> float:
    """The vacuum wavelength: ``--wavelength-nm`` as given, else the instrument's ADM wavelength; both
    given and different is refused in one line naming both (never one silently ignored)."""
    if instrument is None:
        return wavelength_nm
    from multilat.cli.general_adjust import given_options
    from multilat.instrument import load_instrument

    inst_nm = float(load_instrument(instrument).adm.wavelength_nm)
    if "wavelength_nm" in given_options({"wavelength_nm": wavelength_nm}) and wavelength_nm != inst_nm:
        raise MultilatError(f"--wavelength-nm {wavelength_nm:g} contradicts adm.wavelength_nm = {inst_nm:g} of the "
                            f"instrument {instrument} (drop one)")
    return inst_nm
