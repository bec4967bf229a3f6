"""``reach-run completion bash``: a bash completion script, no dependency.

It completes the command words, each command's options (read from the same table
``reach-run --help`` prints) and file names elsewhere. Install it with
``source <(reach-run completion bash)`` in ``~/.bashrc``, or save it to
``/etc/bash_completion.d/reach-run``.
"""

from __future__ import annotations

from collections.abc import Mapping

#: The options each command takes, beside -h/--help and --version.
OPTIONS: dict[str, str] = {
    "run": "--site --sim --out --detach --no-report --seed --compression --effects -q -v",
    "check": "--site --sim --dry-run --json",
    "status": "--site --all --json",
    "queue": "--site --json",
    "attach": "--site",
    "cancel": "--site",
    "abort": "--site",
    "resume": "--site",
    "metrics": "--site --database --since --until --all --csv --json",
    "recover": "--json",
    "completion": "bash",
}


def bash_script(commands: Mapping[str, object]) -> str:
    """The script: ``complete -F _reach_run reach-run``."""
    cases = "\n".join(
        f'        {name}) opts="{OPTIONS.get(name, "")} --help --version" ;;' for name in commands
    )
    return f"""# bash completion for reach-run (reach-run completion bash)
_reach_run() {{
    local cur=${{COMP_WORDS[COMP_CWORD]}} opts
    if [ "$COMP_CWORD" -eq 1 ]; then
        COMPREPLY=($(compgen -W "{' '.join(commands)} --help --version" -- "$cur")
                   $(compgen -f -X '!*.y*ml' -- "$cur") $(compgen -d -- "$cur"))
        return
    fi
    case ${{COMP_WORDS[1]}} in
{cases}
        *) opts="" ;;
    esac
    if [[ $cur == -* ]]; then
        COMPREPLY=($(compgen -W "$opts" -- "$cur"))
    else
        COMPREPLY=($(compgen -f -- "$cur"))
    fi
}}
complete -F _reach_run reach-run"""
