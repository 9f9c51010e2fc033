"""What every command module shares: the subcommands it adds its parser to, and the shape
of the handler it sets as ``run`` (the parsed options and the environment's settings)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeAlias

from ..config import Settings

if TYPE_CHECKING:
    Commands: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

Handler: TypeAlias = Callable[[argparse.Namespace, Settings], None]
