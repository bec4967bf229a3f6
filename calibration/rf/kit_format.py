"""The calibration-kit file's format, as text: imported by ``reach-cal import``'s parser.

Text only (no numpy), so that ``reach-cal import vna --help`` can print it without
loading the engine; :func:`calibration.io.vna_import.read_cal_kit` reads the format.
"""

__all__ = ["KIT_EXAMPLE", "KIT_FORMAT"]

#: EDGES-3's kit as its README (``edges3-2022-319-vna``) describes it.
KIT_EXAMPLE = """{"name": "edges3", "z_ref_ohm": 50,
 "short": {"offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}},
 "open":  {"offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}},
 "load":  {"resistance_ohm": 49.8,
           "offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}}}"""

KIT_FORMAT = f"""kit file (--kit, JSON): "short", "open" and "load" are required ({{}} is that
standard ideal and flush); "name" and "z_ref_ohm" (ohm, default 50) optional.
  short: inductance l0 pH, l1 1e-24 H/Hz, l2 1e-33 H/Hz^2, l3 1e-42 H/Hz^3
  open:  capacitance c0 fF, c1 1e-27 F/Hz, c2 1e-36 F/Hz^2, c3 1e-45 F/Hz^3
  load:  resistance_ohm (default 50); every coefficient defaults to 0
  each may hold "offset": delay_s (one-way, s), loss_gohm_per_s (Gohm/s at
  1 GHz), z0_ohm (default 50). Unknown keys are refused. EDGES-3's kit:
{KIT_EXAMPLE}"""
