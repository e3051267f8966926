"""The SMC100 command table and the emulator's wire behaviour, checked against the user manual rev A812B4
(section
5.5) written out here again: each command page's "Usage" row (states in which the command is executed), its
`?`
form and its error letters; TB's texts; the syntax rules (blanks, CR LF, address, remaining characters); the
state
codes of each fault as the state diagram gives them; and `VE` as real units answer it."""

import pytest

from hamr_bench.clock import VirtualClock
from hamr_bench.instruments import smc100_reference as ref
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol

# Usage rows of the command pages: Not Ref., Config., Disable, Ready, Motion (homing and moving), Jogging.
# Y = executed there. Where the page and the summary table disagree (RS) the page is written here.
USAGE = {
    "AC": ".YYY..", "BA": ".Y....", "BH": ".Y....", "DV": ".Y....", "FD": ".YY...", "FE": ".YY...",
    "FF": ".YY...", "FR": ".Y....", "HT": ".Y....", "ID": ".Y....", "JD": ".....Y", "JM": ".YYY..",
    "JR": ".YYY..", "KD": ".YY...", "KI": ".YY...", "KP": ".YY...", "KV": ".YY...", "MM": "..YY..",
    "OH": ".Y....", "OR": "Y.....", "OT": ".Y....", "PA": "...Y..", "PR": "...Y..", "PT": "..YYY.",
    "PW": "YY....", "QI": ".Y....", "RA": "YYYYYY", "RB": "YYYYYY", "RS": "YYYYY.", "SA": ".Y....",
    "SB": "..YYYY", "SC": ".Y....", "SE": "...Y..", "SL": ".YYY..", "SR": ".YYY..", "ST": "..YYY.",
    "SU": ".Y....", "TB": "YYYYYY", "TE": "YYYYY.", "TH": "YYYYYY", "TP": "YYYYYY", "TS": "YYYYYY",
    "VA": ".YYY..", "VB": ".YYY..", "VE": "YYYYYY", "ZT": "YYYYY.", "ZX": ".Y....",
}
COLUMNS = (("NOT REFERENCED",), ("CONFIGURATION",), ("DISABLE",), ("READY",), ("HOMING", "MOVING"),
           ("JOGGING",))
# Commands with a `?` form (their syntax line has `xxXX?`).
QUERIES = {"AC", "BA", "BH", "DV", "FD", "FE", "FF", "FR", "HT", "ID", "JM", "JR", "KD", "KI", "KP", "KV",
           "MM",
           "OH", "OT", "PA", "PR", "PW", "QI", "SA", "SB", "SC", "SE", "SL", "SR", "SU", "VA", "VB", "ZX"}
NOT_FOR_PP = {"DV", "FD", "FE", "FF", "KD", "KI", "KP", "KV", "SC", "SU"}


def test_the_table_has_every_command_of_the_reference():
    assert set(ref.COMMANDS) == set(USAGE)


@pytest.mark.parametrize("name", sorted(USAGE))
def test_each_row_matches_its_page(name):
    spec = ref.COMMANDS[name]
    columns = zip(USAGE[name], COLUMNS, strict=True)
    executed = {family for flag, families in columns if flag == "Y" for family in families}
    assert spec.states == executed
    assert (spec.query is not None) == (name in QUERIES)
    assert (spec.variant == "CC") == (name in NOT_FOR_PP)


@pytest.mark.parametrize(("name", "family", "letter"), [
    ("PA", "NOT REFERENCED", "H"), ("PA", "DISABLE", "J"), ("PA", "MOVING", "D"), ("PA", "HOMING", "D"),
    ("OR", "READY", "K"), ("OR", "HOMING", "E"), ("OR", "CONFIGURATION", "I"), ("VA", "MOVING", "M"),
    ("VA", "NOT REFERENCED", "H"), ("MM", "NOT REFERENCED", "H"), ("MM", "CONFIGURATION", "I"),
    ("PT", "NOT REFERENCED", "H"), ("ST", "CONFIGURATION", "I"), ("BA", "READY", "K"), ("PW", "READY", "K"),
    ("AC", "JOGGING", "D"),
])
def test_refusal_letters_follow_the_pages_error_lists(name, family, letter):
    assert ref.COMMANDS[name].refusal_letter(family) == letter


def test_error_texts_are_the_te_pages_list():
    assert ref.ERROR_TEXTS["@"] == "No error"
    assert ref.ERROR_TEXTS["H"] == "Command not allowed in NOT REFERENCED state"
    assert sorted(ref.ERROR_TEXTS) == sorted("@ABCDEFGHIJKLMNSUVWX")


# -- on the wire
# --------------------------------------------------------------------------------------------------
class Wire:
    """The protocol on a virtual clock: `ask` sends bytes and returns what came back within `wait_s`."""

    def __init__(self, **params) -> None:
        self.clock = VirtualClock()
        self.emulator = Smc100Emulator(self.clock, Smc100Params(**params))
        self.protocol = Smc100Protocol(self.emulator)

    def ask(self, text: bytes, wait_s: float = 0.1) -> bytes:
        self.protocol.receive(text)
        self.clock.sleep(wait_s)
        return self.protocol.output_until(self.clock.now_s())

    def home(self) -> None:
        assert self.ask(b"1OR\r\n") == b""
        self.clock.sleep(5.0)
        assert self.ask(b"1TS\r\n") == b"1TS000032\r\n"


def test_tb_explains_a_given_letter_and_the_current_error():
    wire = Wire()
    assert wire.ask(b"1TB@\r\n") == b"1TB@ No error\r\n"
    assert wire.ask(b"1TBH\r\n") == b"1TBH Command not allowed in NOT REFERENCED state\r\n"
    assert wire.ask(b"1PA1\r\n") == b""
    assert wire.ask(b"1TB\r\n") == b"1TBH Command not allowed in NOT REFERENCED state\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"  # TB without a code read the error as TE does
    assert wire.ask(b"1TBQ\r\n") == b""  # not a letter of the list: out of range
    assert wire.ask(b"1TE\r\n") == b"1TEC\r\n"


def test_te_then_tb_works_after_an_unknown_command():
    # The failure the issue reports: an unanswered TB stored A and every later TE/TB cycle broke.
    wire = Wire()
    assert wire.ask(b"1XX\r\n") == b""
    assert wire.ask(b"1TE\r\n") == b"1TEA\r\n"
    assert wire.ask(b"1TBA\r\n") == b"1TBA Unknown message code or floating point controller address\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"


def test_th_and_the_query_forms_answer():
    wire = Wire()
    wire.home()
    assert wire.ask(b"1PA2\r\n") == b""
    wire.clock.sleep(5.0)
    assert wire.ask(b"1TH\r\n") == b"1TH2.0001\r\n"  # 2 mm rounded to the 0.3 um step
    assert wire.ask(b"1PA?\r\n") == b"1PA2.0001\r\n"
    assert wire.ask(b"1PR?\r\n") == b"1PR2.0001\r\n"
    assert wire.ask(b"1MM?\r\n") == b"1MM1\r\n"
    assert wire.ask(b"1PW?\r\n") == b"1PW0\r\n"
    assert wire.ask(b"1OT?\r\n") == b"1OT100\r\n"
    assert wire.ask(b"1JR?\r\n") == b"1JR0.005\r\n"
    assert wire.ask(b"1SB?\r\n") == b"1SB0\r\n"
    assert wire.ask(b"1VB?\r\n") == b"1VB0\r\n"
    assert wire.ask(b"1FRM?\r\n") == b"1FRM64\r\n"
    assert wire.ask(b"1FRS?\r\n") == b"1FRS0.0192\r\n"
    assert wire.ask(b"1QIL?\r\n") == b"1QIL1\r\n"
    assert wire.ask(b"1RB\r\n") == b"1RB15\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"


def test_configuration_only_settings_are_set_there_and_read_anywhere():
    wire = Wire()
    assert wire.ask(b"1PW1\r\n") == b""
    assert wire.ask(b"1TS\r\n") == b"1TS000014\r\n"
    assert wire.ask(b"1BA0.005\r\n") == b""
    assert wire.ask(b"1HT1\r\n") == b""
    assert wire.ask(b"1SA3\r\n") == b""
    assert wire.ask(b"1BA?\r\n") == b"1BA0.005\r\n"
    assert wire.ask(b"1HT?\r\n") == b"1HT1\r\n"
    assert wire.ask(b"1SA?\r\n") == b"1SA3\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"
    assert wire.ask(b"1PW0\r\n") == b""
    wire.clock.sleep(6.0)  # saving: deaf for 5 s
    assert wire.ask(b"1TS\r\n") == b"1TS00000C\r\n"
    assert wire.ask(b"1BA0\r\n") == b""  # back in NOT REFERENCED: BA is refused with H
    assert wire.ask(b"1TE\r\n") == b"1TEH\r\n"
    assert wire.ask(b"1BA?\r\n") == b"1BA0.005\r\n"  # saved by PW0


def test_home_type_1_references_where_the_stage_is():
    wire = Wire(initial_position_m=3e-3)
    wire.ask(b"1PW1\r\n")
    wire.ask(b"1HT1\r\n")
    wire.ask(b"1PW0\r\n")
    wire.clock.sleep(6.0)
    wire.home()
    assert wire.ask(b"1TP\r\n") == b"1TP0\r\n"
    assert wire.emulator.position_m(wire.clock.now_s()) == pytest.approx(3e-3)


def test_homing_that_outlasts_the_time_out_ends_not_referenced_with_bit_6():
    wire = Wire(initial_position_m=20e-3)  # 20 mm at 2.5 mm/s takes 8 s
    wire.ask(b"1PW1\r\n")
    wire.ask(b"1OT2\r\n")
    wire.ask(b"1PW0\r\n")
    wire.clock.sleep(6.0)
    wire.ask(b"1OR\r\n")
    wire.clock.sleep(3.0)
    assert wire.ask(b"1TS\r\n") == b"1TS00400B\r\n"
    assert wire.ask(b"1TS\r\n") == b"1TS00000B\r\n"  # reading TS cleared the event bit


def test_blanks_anywhere_are_ignored():
    wire = Wire()
    wire.home()
    assert wire.ask(b"1P A1.43 6\r\n") == b""
    wire.clock.sleep(5.0)
    assert wire.ask(b" 1 T P \r\n") == b"1TP1.4361\r\n"  # 1.436 mm to the 0.3 um step
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"


def test_only_cr_lf_ends_a_command():
    wire = Wire()
    assert wire.ask(b"1TS\r") == b""  # a bare CR: the controller is still waiting for the terminator
    assert wire.ask(b"1TS\n") == b""
    # once CR LF arrives the line is "1TS\r1TS\n1TS": TS is executed and the rest ignored, as the reference
    # says
    assert wire.ask(b"1TS\r\n") == b"1TS00000A\r\n"
    assert wire.ask(b"1TS\n") == b""


def test_lower_case_trailing_question_mark_and_remaining_characters():
    wire = Wire()
    # TS takes nothing: the ? is ignored (public drivers send it)
    assert wire.ask(b"1ts?\r\n") == b"1TS00000A\r\n"
    assert wire.ask(b"1tp?\r\n") == b"1TP0\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"


@pytest.mark.parametrize(("line", "letter"), [
    (b"TS\r\n", "B"),  # address missing (TS may not be broadcast)
    (b"40TS\r\n", "B"),  # out of range
    (b"1.5TS\r\n", "A"),  # floating point address
    (b"1Q\r\n", "A"),
    (b"1KP0.1\r\n", "W"),  # a servo gain: not for the PP
    (b"1PA\r\n", "H"),  # refused in NOT REFERENCED before its missing value is looked at
])
def test_bad_addresses_and_commands_store_their_letters(line, letter):
    wire = Wire()
    assert wire.ask(line) == b""
    assert wire.ask(b"1TE\r\n") == f"1TE{letter}\r\n".encode()


def test_other_addresses_are_ignored_and_broadcast_st_reaches_everyone():
    wire = Wire()
    wire.home()
    assert wire.ask(b"2TS\r\n") == b""
    assert wire.ask(b"1PA10\r\n") == b""
    assert wire.ask(b"ST\r\n", wait_s=1.0) == b""
    assert wire.ask(b"1TS\r\n") == b"1TS000033\r\n"
    assert wire.ask(b"1TE\r\n") == b"1TE@\r\n"


def test_ve_reports_the_controller_revision():
    assert Wire().ask(b"1VE\r\n") == b"1VE SMC_PP - Controller-driver version  3. 1. 2\r\n"


def test_zt_lists_the_configuration_between_pw1_lines():
    lines = Wire().ask(b"1ZT\r\n").decode().split("\r\n")[:-1]
    assert lines[0] == lines[-1] == "1PW1"
    assert "1AC20.000000" in lines and "1VA5.000000" in lines and "1SL-50.000000" in lines and "1ZX3" in lines
    assert [line[1:3] for line in lines[1:-1]] == sorted(line[1:3] for line in lines[1:-1])


@pytest.mark.parametrize(("start", "code"), [("moving", 0x0F), ("ready", 0x0E), ("disable", 0x0D)])
def test_end_of_run_falls_to_not_referenced_from_the_state_it_left(start, code):
    wire = Wire()
    wire.home()
    if start == "moving":
        wire.ask(b"1PA20\r\n")
    if start == "disable":
        wire.ask(b"1MM0\r\n")
    wire.emulator.faults.inject("end_of_run")
    reply = wire.ask(b"1TS\r\n")
    assert reply == f"1TS0002{code:02X}\r\n".encode()
    # the stage still sits on the switch: the bit is reported again
    assert wire.ask(b"1TS\r\n") == reply


def test_end_of_run_while_homing_is_checked_when_homing_ends():
    wire = Wire(initial_position_m=2e-3)
    wire.ask(b"1OR\r\n")
    wire.emulator.faults.inject("end_of_run")
    assert wire.ask(b"1TS\r\n")[-4:] == b"1E\r\n"
    wire.clock.sleep(5.0)
    assert wire.ask(b"1TS\r\n") == b"1TS00010B\r\n"


def test_following_error_in_a_move_disables_and_ts_clears_the_bit():
    wire = Wire()
    wire.home()
    wire.ask(b"1PA20\r\n")
    wire.emulator.faults.inject("following_error")
    assert wire.ask(b"1TS\r\n") == b"1TS00203D\r\n"
    assert wire.ask(b"1TS\r\n") == b"1TS00003D\r\n"
    assert wire.ask(b"1MM1\r\n") == b""
    assert wire.ask(b"1TS\r\n") == b"1TS000034\r\n"


def test_reset_restores_the_saved_working_settings():
    wire = Wire(reset_time_s=0.5)
    wire.home()
    wire.ask(b"1VA2\r\n")
    wire.ask(b"1SL-10\r\n")
    assert wire.ask(b"1VA?\r\n") == b"1VA2\r\n"
    wire.ask(b"1RS\r\n", wait_s=1.0)
    assert wire.ask(b"1VA?\r\n") == b"1VA5\r\n"
    assert wire.ask(b"1SL?\r\n") == b"1SL-50\r\n"


def test_simultaneous_start():
    wire = Wire()
    wire.home()
    assert wire.ask(b"1SE1\r\n") == b""
    assert wire.ask(b"1SE?\r\n") == b"1SE0.9999\r\n"  # rounded to the 0.3 um step
    assert wire.ask(b"1TS\r\n") == b"1TS000032\r\n"  # stored, not started
    assert wire.ask(b"SE\r\n", wait_s=2.0) == b""
    assert wire.ask(b"1TP\r\n") == b"1TP0.9999\r\n"
