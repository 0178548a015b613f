"""The study's options, each declared once (docs/maintaining.md principle 9).

A study option is a ``StudyParams`` field made with ``option(...)``: its flag, its kind (parser and bounds),
what ``none`` means for it, its unit, its help, whether ``homocal sweep`` can sweep it, whether study.json
leaves it out at its default, and its value in each preset (``PRESETS``). Everything else is derived from
the declarations: the library check (errors name the parameter), study.json's form (``to_json`` /
``from_json``), the study and sweep parsers (homocal.study.cli, homocal.study.sweep), the report's labels
(``option_text``, ``changed_options``) and the docs' option table (``options_markdown``). A field that is
not an option is declared ``internal(...)`` with the reason.

Adding an option: one ``option(...)`` field in StudyParams, plus the code that uses its value.
"""
from __future__ import annotations

import argparse
import math
import numbers
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Callable

from homocal.arguments import range_text, within


@dataclass(frozen=True)
class Preset:
    """A preset of `homocal study --preset`: label, what the configuration is (the help, the report's label and
    study.json say it); details, how. Each option's declaration holds its value in each preset (as the text its
    flag takes); an option without one keeps its default."""

    label: str
    details: str


PRESETS = {
    "quick": Preset("a quick look", "50 variants, every other option at its default"),
    "paper": Preset("the paper's protocol as the paper states it",
                    "fixed before any result was seen: the hand-placed trapezoid as it is (its image corners 1.4-1.9 px "
                    "and its map corners 1.1-1.8 map px from the exact trapezoid's in both scenes, within the 0-3 px "
                    "the paper calls the typical inaccuracy of careful placement), the per-coordinate perturbation "
                    "(Section 5.2), the dataset's own site map, descent's library defaults (the paper gives no "
                    "delta_max) and range errors (Section 3 defines the distance estimation error as Y_hat - Y, "
                    "Section 6 reports its relative improvement), 1000 variants, 2000 test points"),
    "table1-fit": Preset("fitted to Table 1, not the paper's protocol",
                         "the open choices that brought the numbers closest to the paper's Table 1: the clicked "
                         "trapezoid's horizon 16 px above the true one (4-6x the paper's 0-3 px), one positive 0-3 px "
                         "size per variant, a 1.5 px/m site map, descent's largest move 18 px, range errors; 1000 "
                         "variants, 2000 test points"),
}
DEFAULT_PRESET = "quick"


class OptionError(ValueError):
    """A bad value of a study option; the message names the StudyParams parameter, ``expected`` says what it
    takes (the CLI puts the flag in front of it instead)."""

    def __init__(self, name: str, value: Any, expected: str):
        self.name, self.value, self.expected = name, value, expected
        super().__init__(f"{name} {value!r}: {expected}")


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


@dataclass(frozen=True)
class Number:
    """A finite number in [low, high] ((low, high] if low_open); an integer if integer."""

    low: float
    high: float = math.inf
    low_open: bool = False
    integer: bool = False

    def describe(self) -> str:
        return f"{'an integer' if self.integer else 'a number'} {range_text(self.low, self.high, self.low_open)}"

    def check(self, value: Any) -> Any:
        if not (_is_number(value) and (isinstance(value, numbers.Integral) or not self.integer)
                and within(value, self.low, self.high, self.low_open)):
            raise ValueError
        return int(value) if self.integer else value if isinstance(value, (int, float)) else float(value)

    def from_text(self, text: str) -> Any:
        try:
            value = (int if self.integer else float)(text)
        except ValueError:
            raise ValueError from None
        return self.check(value)

    def to_text(self, value: Any) -> str:
        return str(value) if self.integer else f"{value:g}"


@dataclass(frozen=True)
class Words:
    """One of words; any non-empty text without words (a name checked where it is used)."""

    words: tuple[str, ...] = ()

    def describe(self) -> str:
        return "one of " + ", ".join(self.words) if self.words else "a non-empty name"

    def check(self, value: Any) -> Any:
        if not (isinstance(value, str) and value and (value in self.words or not self.words)):
            raise ValueError
        return value

    def from_text(self, text: str) -> Any:
        return self.check(text)

    def to_text(self, value: Any) -> str:
        return value


@dataclass(frozen=True)
class YesNo:
    """True or False, written yes or no; with auto, also "auto" (the user of the value decides), written auto."""

    auto: bool = False

    @property
    def choices(self) -> tuple[str, ...]:
        """The words it takes."""
        return ("yes", "no", "auto") if self.auto else ("yes", "no")

    def describe(self) -> str:
        return ", ".join(self.choices[:-1]) + " or " + self.choices[-1]

    def check(self, value: Any) -> Any:
        if not (isinstance(value, bool) or (self.auto and isinstance(value, str) and value == "auto")):
            raise ValueError
        return value

    def from_text(self, text: str) -> Any:
        if text not in self.choices:
            raise ValueError
        return text if text == "auto" else text == "yes"

    def to_text(self, value: Any) -> str:
        return value if value == "auto" else "yes" if value else "no"


@dataclass(frozen=True)
class Parsed:
    """A value kept parsed in StudyParams and written as text in study.json (e.g. perturb.ShiftSpec): parse(text)
    gives it (a ValueError saying what it expects), str() gives its text; check takes it parsed, as text or as
    a number."""

    kind: type
    parse: Callable[[str], Any]
    expected: str

    def describe(self) -> str:
        return self.expected

    def check(self, value: Any) -> Any:
        if isinstance(value, self.kind):
            return value
        if _is_number(value):
            return self.parse(str(value))
        return self.from_text(value)

    def from_text(self, text: Any) -> Any:
        if not isinstance(text, str):
            raise ValueError
        return self.parse(text)

    def to_text(self, value: Any) -> str:
        return str(value)

    def to_json(self, value: Any) -> Any:
        return str(value)


@dataclass(frozen=True)
class Via:
    """A field of settings set through one option value: from_value(option value) gives the settings,
    to_value(settings) the option value, normalize(settings) their one spelling, to_json(settings) their
    study.json form (e.g. descent's settings through its largest move, delta_max)."""

    option_kind: Any
    from_value: Callable[[Any], Any]
    to_value: Callable[[Any], Any]
    normalize: Callable[[Any], Any]
    to_json: Callable[[Any], Any]

    def describe(self) -> str:
        return self.option_kind.describe()

    def check(self, value: Any) -> Any:
        if not isinstance(value, dict):
            raise ValueError
        self.option_kind.check(self.to_value(value))
        return self.normalize(value)

    def from_text(self, text: str) -> Any:
        return self.from_value(self.option_kind.from_text(text))

    def to_text(self, value: Any) -> str:
        return self.option_kind.to_text(self.to_value(value))


@dataclass(frozen=True)
class Option:
    """A study option's declaration (the metadata of its StudyParams field).

    flag: its command-line flag; kind: its parser and bounds (Number, Words, Parsed, Via);
    help: what it sets; metavar: the flag's value in the help; unit: of its values ("px", "m", "px/m");
    none: what the value None ('none' on the command line) means, "" if None is not allowed; sweep: whether
    homocal sweep can sweep it; omit_default: left out of study.json at its default (options added after
    studies were written, whose keys must not change); presets: its value per preset name, as its flag takes it.
    """

    flag: str
    kind: Any
    help: str
    metavar: str | None = None
    unit: str = ""
    none: str = ""
    sweep: bool = False
    omit_default: bool = False
    presets: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The option's name without dashes ("descent_delta_max"): sweep's parameter and run folder names."""
        return self.flag.lstrip("-").replace("-", "_")

    def expected(self) -> str:
        return self.kind.describe() + (f" ({self.unit})" if self.unit else "") + (" or none" if self.none else "")

    def check(self, name: str, value: Any) -> Any:
        """value as StudyParams keeps it; OptionError naming the parameter name otherwise."""
        if value is None and self.none:
            return None
        try:
            return self.kind.check(value)
        except (ValueError, TypeError, KeyError) as e:
            raise OptionError(name, value, self._reason(e)) from None

    def from_text(self, text: str) -> Any:
        """The value the flag's text gives ('none' -> None where allowed); ValueError saying what it expects."""
        if self.none and text.strip().lower() == "none":
            return None
        try:
            return self.kind.from_text(text)
        except ValueError as e:
            raise ValueError(f"{self._reason(e)}, got {text!r}") from None

    def _reason(self, error: Exception) -> str:
        """A kind's own reason (ShiftSpec.parse's), or what the option takes (a kind's bare ValueError)."""
        return str(error) if isinstance(error, ValueError) and str(error) else "expected " + self.expected()

    def to_text(self, value: Any) -> str:
        """The flag's text of value (from_text's inverse)."""
        return "none" if value is None else self.kind.to_text(value)

    def to_json(self, value: Any) -> Any:
        """value as study.json holds it."""
        return value if value is None else getattr(self.kind, "to_json", lambda v: v)(value)


def flag_type(opt: Option):
    """The argparse type of an option's flag: its from_text, refusals as argparse errors naming the flag."""
    def parse(text: str):
        try:
            return opt.from_text(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return parse


def option(default: Any = MISSING, *, default_factory: Any = MISSING, **declaration) -> Any:
    """A StudyParams field that is a study option (Option's arguments as keywords)."""
    return field(default=default, default_factory=default_factory, metadata={"option": Option(**declaration)})


def internal(default: Any = MISSING, *, default_factory: Any = MISSING, why: str) -> Any:
    """A StudyParams field that no option sets (why: the reason, for the reader and the declarations test)."""
    return field(default=default, default_factory=default_factory, metadata={"internal": why})


def declared_options(cls) -> dict[str, Option]:
    """{field name: Option} of the dataclass cls, in field order."""
    return {f.name: f.metadata["option"] for f in fields(cls) if "option" in f.metadata}


def preset_values(cls, preset: str) -> dict[str, Any]:
    """{field name: value} the preset sets (each option's declared text parsed); ValueError for an unknown preset."""
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: expected one of {', '.join(PRESETS)}")
    return {name: opt.from_text(opt.presets[preset]) for name, opt in declared_options(cls).items() if preset in opt.presets}


def options_markdown(cls) -> str:
    """The docs' option table of the dataclass cls as Markdown: flag, parameter, values, sweepable, default,
    the value in each preset (declared or default), help."""
    default, presets = cls(), {p: cls(**preset_values(cls, p)) for p in PRESETS}
    head = ["option", "parameter", "values", "sweep", "library default", *(f"`--preset {p}`" for p in PRESETS), "meaning"]
    rows = [head, ["---"] * len(head)]
    for name, opt in declared_options(cls).items():
        values = opt.expected() + (f" ({opt.none})" if opt.none else "")
        rows.append([f"`{opt.flag}`", f"`{name}`", values, "yes" if opt.sweep else "",
                     *(f"`{opt.to_text(getattr(p, name))}`" for p in (default, *presets.values())), opt.help])
    return "\n".join("| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows) + "\n"
