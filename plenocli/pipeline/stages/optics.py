"""Stage ``optics``: a lens prescription YAML -> its figures (printed; optionally JSON)."""

from __future__ import annotations

import json as _json
import math

from plenocli.errors import ConfigError
from plenocli.io.atomic import write_text
from plenocli.io.lensfile import read_lens
from plenocli.model.provenance import json_safe, stage_record
from plenocli.optics.analysis import lens_report
from plenocli.optics.crosstalk import crosstalk_report


def run(input: str, *, sensor_mm: float = 3.6, json: str | None = None,
        crosstalk: bool = False, mask_width: float = 1 / 15, pixel_um: float = 1.2,
        object_distance_mm: float = 2000.0, prism_n: float = 1.74,
        prism_apex_deg: float = 16.7) -> dict:
    """Compute the figures of the lens in ``input``; write them to ``json`` when given.

    Returns the report (the CLI prints it with :func:`format_report`).
    """
    lens = read_lens(input)
    try:
        report = lens_report(lens, sensor_mm=sensor_mm, prism_n=prism_n,
                             prism_apex_deg=prism_apex_deg)
        if crosstalk:
            report["crosstalk"] = crosstalk_report(
                lens, cross_width_fraction=mask_width, sensor_mm=sensor_mm, pixel_um=pixel_um,
                object_distance_mm=object_distance_mm)
    except ValueError as err:
        raise ConfigError(_blamed(input, err)) from err
    if json:
        params = dict(sensor_mm=sensor_mm, crosstalk=crosstalk, mask_width=mask_width,
                      pixel_um=pixel_um, object_distance_mm=object_distance_mm,
                      prism_n=prism_n, prism_apex_deg=prism_apex_deg)
        doc = {**report, "provenance": stage_record("optics", params, {"input": input})}
        write_text(json, _json.dumps(json_safe(doc), indent=1, allow_nan=False) + "\n",
                   protect=(input,))
    return report


# the library's names of values an option gives: its message is the option's, not the lens's
OPTION_OF = {"cross_width_fraction": "--mask-width", "object_distance_mm": "--object-distance-mm"}


def _blamed(input: str, err: ValueError) -> str:
    """The library's message, led by the option whose value it names, else by the lens file."""
    name, _, rest = str(err).partition(" ")
    return f"{OPTION_OF[name]} {rest}" if name in OPTION_OF else f"{input}: {err}"


def format_report(report: dict) -> str:
    """The figures as aligned text lines."""
    fov = report["field_of_view_deg"]
    enp, exp = report["entrance_pupil"], report["exit_pupil"]
    lines = [
        f"lens                      {report['lens']}  (lambda {report['wavelength_um']} um)",
        f"effective focal length    {report['efl_mm']:.4f} mm",
        f"back focal distance       {report['bfd_mm']:.4f} mm (image plane at "
        f"{report['image_distance_mm']:.4f} mm, {report['focus_offset_mm']:+.4f} mm from focus)",
        f"f-number                  {report['f_number']:.3f}",
        f"entrance pupil            z {enp['z_mm']:.4f} mm, diameter {enp['diameter_mm']:.4f} mm",
        f"exit pupil                z {exp['z_mm']:.4f} mm, diameter {exp['diameter_mm']:.4f} mm,"
        f" {exp['distance_to_image_mm']:.4f} mm before the image plane (D)",
        f"field of view ({report['sensor_mm']} mm)   {fov['horizontal']:.2f} deg horizontal, "
        f"{fov['diagonal']:.2f} deg diagonal (paraxial {fov['paraxial_horizontal']:.2f} deg)",
        "distortion                " + ", ".join(
            f"{d['percent']:+.3f} % @ {d['field_deg']:.1f} deg"
            for d in report["distortion_percent"]),
        f"max |distortion|          {report['max_abs_distortion_percent']:.3f} %",
        "RMS spot radius           " + ", ".join(
            f"{s['rms_um']:.2f} um @ {s['field_deg']:.1f} deg" for s in report["spot_rms_um"]),
    ]
    p = report["prism"]
    normal = p["normal_incidence_deg"]
    apex = p["apex_for_half_field_deg"]
    lines.append(f"prism n {p['n']}, A {p['apex_deg']} deg  deviation {p['thin_deg']:.3f} deg "
                 f"(n-1)A, {p['minimum_deg']:.3f} deg exact minimum, "
                 + (f"{normal:.3f} deg at normal incidence" if normal == normal else
                    "none at normal incidence (totally reflected: n sin A > 1)")
                 + "; A for alpha = half field: "
                 + (f"{apex:.2f} deg (exact, at minimum deviation)" if apex is not None else
                    f"none (a prism of index {p['n']} deviates light by at most "
                    f"{p['max_minimum_deviation_deg']:.2f} deg at minimum deviation)"))
    ct = report.get("crosstalk")
    if ct:
        def pct(v):
            return "inf" if math.isinf(v) else f"{100 * v:.1f} %"
        lines.append(f"cross-talk (quarter {ct['quarter']} open, MLA pitch "
                     f"{ct['microlens_pitch_um']:.4f} um)  r = {pct(ct['no_mask']['ratio'])}; with"
                     f" a cross of {ct['cross_mask']['cross_width_mm']:.3f} mm: "
                     f"{pct(ct['cross_mask']['ratio'])} (cross removes "
                     f"{pct(ct['cross_mask_flux_loss'])} of the flux)")
    return "\n".join(lines)
