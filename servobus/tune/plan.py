"""What every front end checks and says before a tuning run (the CLI's ``servobus tune``, the
GUI's Tuning tab "Auto"): the same rules and the same words, whoever asks.

:func:`check_save` refuses ``save`` where the family does not save with a command (before
anything moves), :func:`question` is the confirmation naming the axis and the distance (in
the axis's unit, as the front end shows it), :func:`write_note` the EEPROM note of the
families that write every gain to EEPROM. The gains to keep by hand (the DYN5: RAM only,
DMMDRV5 saves them) are the result's ``save_hint`` beside its kept and tuned gains.
"""

from __future__ import annotations

from servobus.axis.types import Persistence, TuningProfile
from servobus.errors import ArgumentRangeError
from servobus.tune.tuner import EEPROM_WRITE_BUDGET


def check_save(profile: TuningProfile | None, family_title: str, save: bool) -> None:
    """ArgumentRangeError (nothing moved) when ``save`` is asked of gains no command saves."""
    if save and not saves_with_command(profile):
        hint = profile.save_hint if profile is not None else "no tuning gains"
        raise ArgumentRangeError(f"{family_title} gains are not saved with a command "
                                 f"({hint}); nothing was moved")


def saves_with_command(profile: TuningProfile | None) -> bool:
    """Whether the family keeps tuned gains only when asked to save (YZ-AIM, 0x14)."""
    return profile is not None and profile.persistence is Persistence.RAM_SAVE_COMMAND


def question(who: str, shown: str) -> str:
    """The confirmation: ``who`` names the axis, ``shown`` the distance in its unit."""
    return (f"tune {who}: test moves between here and {shown} away, gains raised until "
            "the motor vibrates; go?")


def write_note(profile: TuningProfile | None) -> str | None:
    """What a run costs the drive's EEPROM, where every gain write goes there."""
    if profile is not None and profile.persistence is Persistence.EEPROM_EACH_WRITE:
        return (f"note: every gain write goes to the drive's EEPROM (at most "
                f"{EEPROM_WRITE_BUDGET} this run)")
    return None
