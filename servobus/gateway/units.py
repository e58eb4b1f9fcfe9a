"""OPC UA EngineeringUnits for the machine file's units (UNECE Recommendation 20 codes).

OPC UA (Part 8, 5.6.3) names units by their UNECE common code; UnitId is the code's
letters packed into an integer. A unit without a code here keeps its text as the
DisplayName and UnitId -1 (OPC UA's "unknown").
"""

from __future__ import annotations

from asyncua import ua

UNECE_URI = "http://www.opcfoundation.org/UA/units/un/cefact"

#: unit text -> (UNECE common code, description)
CODES: dict[str, tuple[str, str]] = {
    "mm": ("MMT", "millimetre"), "mm/s": ("C16", "millimetre per second"),
    "m": ("MTR", "metre"), "m/s": ("MTS", "metre per second"),
    "um": ("4H", "micrometre"), "µm": ("4H", "micrometre"),
    "in": ("INH", "inch"), "in/s": ("IU", "inch per second"),
    "deg": ("DD", "degree"), "deg/s": ("E96", "degree per second"),
    "rad": ("C81", "radian"), "rad/s": ("2A", "radian per second"),
    "rev": ("M44", "revolution"), "rev/s": ("RPS", "revolutions per second"),
    "A": ("AMP", "ampere"), "°C": ("CEL", "degree Celsius"),
}


def unit_id(code: str) -> int:
    value = 0
    for ch in code:
        value = (value << 8) | ord(ch)
    return value


def eu_information(unit: str) -> ua.EUInformation:
    code = CODES.get(unit)
    info = ua.EUInformation()
    info.NamespaceUri = UNECE_URI
    info.UnitId = unit_id(code[0]) if code else -1
    info.DisplayName = ua.LocalizedText(unit)
    info.Description = ua.LocalizedText(code[1] if code else unit)
    return info
