"""mkdocs hooks: the command-line reference and the parameter table written from the code,
and Sphinx roles in rendered docstrings shown as plain code.

The page ``reference/cli.md`` holds the marker ``<!-- cli-reference -->``; at build time it
is replaced by one section per command (its help text and a table of its options with the
defaults), read from the Typer application itself, so the reference cannot drift from
``maglev-match COMMAND --help``. Likewise ``<!-- parameter-table -->`` becomes the table of
every parameter with its unit, meaning and default.
"""

from __future__ import annotations

import re

MARKER = "<!-- cli-reference -->"


def _unwrap(text: str | None) -> str:
    """Help texts are written as wrapped docstrings: join the lines of each paragraph."""
    if not text:
        return ""
    paragraphs = re.split(r"\n\s*\n", text.strip())
    return "\n\n".join(" ".join(line.strip() for line in p.splitlines()) for p in paragraphs)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _default(param) -> str:
    if getattr(param, "is_flag", False):
        return "on" if param.default else "off"
    if param.default is None or param.default == ():
        return "required" if param.required else ""
    return f"`{param.default}`"


def cli_reference() -> str:
    """The reference as Markdown: the program's help, then every command."""
    import typer

    from maglev_match.cli import all_commands, app

    group = typer.main.get_command(app)
    lines = [_unwrap(group.help), ""]
    for name, cmd in all_commands().items():  # (the program loads its commands lazily)
        lines += [f"## `maglev-match {name}`", "", _unwrap(cmd.help), "",
                  "| option | default | meaning |", "|---|---|---|"]
        for p in cmd.params:
            if p.name == "help":
                continue
            opts = " / ".join(f"`{o}`" for o in [*p.opts, *p.secondary_opts])
            if p.param_type_name == "argument":  # a positional argument: its form
                opts = f"`{p.metavar or p.name.upper()}` (positional)"
            if getattr(p, "multiple", False):
                opts += " (repeatable)"
            lines.append(f"| {opts} | {_cell(_default(p))} | {_cell(_unwrap(p.help))} |")
        lines.append("")
    return "\n".join(lines)




PARAMETER_MARKER = "<!-- parameter-table -->"
SECTIONS = {
    "levitation unit (model A)": ("m", "M", "g", "ks", "cs", "mu0", "N", "A", "c0"),
    "controller": ("omega0", "xi0", "kP", "kD", "ke"),
    "beam": ("xi1", "L", "EI", "mbar", "omega1", "sigma"),
    "vehicle": ("l", "k", "m_s", "j_s", "m_b", "j_b", "k2", "c2", "s", "s0", "n_modes"),
    "physical limits": ("gap_min", "gap_max"),
}


def parameter_table() -> str:
    """Every parameter with its unit, meaning and default (the default preset's value for
    the derived ones), from the parameter table of the package."""
    from maglev_match.core.params import PARAMETER_DOCS, load_preset

    p = load_preset()
    derived = {"omega1", "sigma", "s", "s0"}
    lines = ["| name | unit | meaning | default |", "|---|---|---|---|"]
    listed: set[str] = set()
    for section, names in SECTIONS.items():
        lines.append(f"| **{section}** | | | |")
        for n in names:
            unit, meaning = PARAMETER_DOCS[n]
            v = getattr(p, n)
            text = f"{v:.6g}" if isinstance(v, float) else str(v)
            if n in derived:
                text += " (derived)"
            lines.append(f"| `{n}` | {unit} | {_cell(meaning)} | {text} |")
            listed.add(n)
    others = [n for n in PARAMETER_DOCS if n not in listed]
    if others:  # parameters added since the sections above were written
        lines.append("| **other** | | | |")
        for n in others:
            unit, meaning = PARAMETER_DOCS[n]
            v = getattr(p, n, "")
            text = f"{v:.6g}" if isinstance(v, float) else str(v)
            lines.append(f"| `{n}` | {unit} | {_cell(meaning)} | {text} |")
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    """mkdocs event: fill the markers of the CLI reference and the parameter table."""
    if MARKER in markdown:
        markdown = markdown.replace(MARKER, cli_reference())
    if PARAMETER_MARKER in markdown:
        markdown = markdown.replace(PARAMETER_MARKER, parameter_table())
    return markdown


# Docstrings in the package use Sphinx roles (:func:`name`); mkdocstrings renders them as
# ":func:<code>name</code>". Show the name alone (the last component for "~a.b.c").
_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):<code>~?([\w.]+)</code>")


def on_page_content(html: str, page, config, files) -> str:
    """mkdocs event: drop the Sphinx role prefixes left in rendered docstrings."""
    return _ROLE.sub(lambda m: f"<code>{m.group(1)}</code>", html)
