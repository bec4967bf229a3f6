"""``reach-cal``, the engine's command line: one module per command, parsers kept light.

:mod:`.main` builds the parser (from :mod:`.args` and :mod:`.import_parser`, which import
nothing of the engine) and runs a command by importing its module: :mod:`.simulate`,
:mod:`.solve`, :mod:`.apply`, :mod:`.summary`, :mod:`.validate`, :mod:`.report`,
:mod:`.import_commands`. :mod:`.corrections` is what ``solve``'s preparation and
consistency options do; :mod:`.files` keeps every command off its inputs.
"""

from .main import main

__all__ = ["main"]
