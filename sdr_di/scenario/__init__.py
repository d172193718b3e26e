"""Scenario files (TOML): schema, validation, the shipped default."""

from pathlib import Path

from .schema import Scenario, load_scenario, parse_scenario

#: Repository root (the package is used from a checkout: ``pip install -e .``).
REPO_ROOT = Path(__file__).resolve().parents[2]
#: The shipped paper-004 scenario.
DEFAULT_SCENARIO = REPO_ROOT / "signals" / "default.toml"

__all__ = ["Scenario", "load_scenario", "parse_scenario", "DEFAULT_SCENARIO", "REPO_ROOT"]
