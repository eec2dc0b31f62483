"""What a CiA 402 drive's quick stop does, as its quick stop option code (object 0x605A) says:
the text of the protection's action when the abort connection option code (0x6007) is 3, quick
stop (:mod:`drivers.cia402.protection`).

The driver neither writes 0x605A nor the decelerations it names (0x6084 profile deceleration,
0x6085 quick stop deceleration): they are the drive's, set with the vendor's tool.  It reads
0x605A while enabling (:func:`~drivers.cia402.steps.protection_steps`) and says what the value
means, so the action reported is the drive's own and not an assumption.  The values (CiA 402-2 /
IEC 61800-7-201, object 605Ah; as the Beckhoff EtherCAT Slave Stack Code's CiA 402 sample
``cia402appl.h`` lists them, e.g. in the public repository
DieBieEngineering/DieBieSlave-Firmware-Nunchuck, ``Middlewares/SSC/Inc/cia402appl.h``):

* 0 disable drive function: the power stage switches off at once and the motor **coasts**: no
  braking to standstill (a warning);
* 1 slow down on the slow-down ramp, 2 on the quick-stop ramp, 3 at the current limit, 4 at the
  voltage limit, then SWITCH ON DISABLED (the power stage off, at standstill);
* 5 to 8 as 1 to 4, then stay in QUICK STOP ACTIVE (powered, held at standstill);
* -32768 to -1 manufacturer-specific, 9 to 32767 reserved: not known here (a warning).

0x605A is optional: a drive without it answers the read with SDO abort 0x06020000 "object does
not exist", and the action stays the profile's usual default, 2, marked as assumed (e.g. the
Beckhoff AX8000 object description of 0x605A gives 2 as its default).
"""

from __future__ import annotations

from drivers.cia402.faults import sdo_abort_text

#: The abort connection option code (0x6007) of a quick stop, whose action 0x605A says.
ABORT_QUICK_STOP = 3
#: What each quick stop option code does (CiA 402), after "slow down" where it slows down.
_RAMPS = {1: "on the slow-down ramp (0x6084 profile deceleration)",
          2: "on the quick-stop ramp (0x6085 quick stop deceleration)",
          3: "at the current limit", 4: "at the voltage limit"}
#: The quick stop option code the profile names as usual default (assumed when unknown).
USUAL_DEFAULT = 2
#: The codes whose quick stop brakes the motor to standstill (0 lets it coast; what
#: manufacturer-specific and reserved codes do is not known here).
BRAKES = range(1, 9)
#: The codes after which the drive stays in QUICK STOP ACTIVE.
STAYS = range(5, 9)


def meaning(option: int) -> str:
    """What quick stop option code ``option`` does, in words."""
    if option == 0:
        return "disable drive function: the power stage switches off at once, the motor coasts"
    base = option - 4 if option in STAYS else option
    if base in _RAMPS:
        end = ("then stays in QUICK STOP ACTIVE (powered, held at standstill)"
               if option in STAYS else "then SWITCH ON DISABLED")
        return f"slow down {_RAMPS[base]} to standstill, {end}"
    if option < 0:
        return "manufacturer-specific: see the drive's manual"
    return "reserved: not a CiA 402 quick stop option code"


def quick_stop_action(option: int | None, abort: int | None = None) -> tuple[str, bool]:
    """The protection's action for abort connection option 3 (quick stop), and whether it
    deserves a warning (the motor coasts, or what it does is not known).

    :param option: 0x605A as the drive answered; ``None`` if not read (yet, or refused).
    :param abort: the SDO abort code the drive answered the read with, if it did (a warning:
        the action is then assumed).
    """
    head = "quick stop (0x605A quick stop option code"
    if option is not None:
        text = f"{head} = {option}, read from the drive: {meaning(option)})"
        return text, option not in BRAKES
    assumed = f"assumed {USUAL_DEFAULT}, the profile's usual default: {meaning(USUAL_DEFAULT)}"
    if abort is None:
        return f"{head} not read yet; {assumed})", False
    return f"{head} not known, its read was aborted with {sdo_abort_text(abort)}; {assumed})", True
