"""Configuration: the site file and each instrument's typed settings, checked with line numbers.

:mod:`.yaml_lines` loads YAML safely, remembering the line of every key; :mod:`.fields`
reads a mapping with types and ranges, recording every mistake as ``file:line: key:
message``; :mod:`.settings` declares each instrument's settings once (units, defaults,
ranges); :mod:`.site` reads the site file with them. The schedule language builds on the
same loader and readers.
"""
