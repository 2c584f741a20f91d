"""What GitLab's JUnit import does to a result file, and how a file is kept safe from it.

GitLab keys a case by ``<suite>_<classname>_<name>`` and keeps one per key, and turns a
``type`` attribute it knows into something else. ``normalise`` applies these rules to a
producer's cases, ``attempts`` to a merge of a rerun's attempts and ``serialise`` to
every ``type`` it writes; their own module, so none of those needs another for them.
"""

from __future__ import annotations

from ros_isolated_test.xunit.model import Attempt, Case
from ros_isolated_test.xunit.xml_text import name_token

#: Characters kept of a ``type`` attribute.
TYPE_LIMIT = 256
#: ``type`` values GitLab's XML converter (ActiveSupport's ``Hash.from_xml``, matched
#: exactly as written) acts on: ``symbol`` and ``yaml`` are refused, which drops the whole
#: file; ``date``/``datetime`` fail on text that is no date; the others turn the element's
#: text into a number, a decoded blob or an empty list. ``string`` is harmless.
GITLAB_CONVERTED_TYPES = frozenset(
    {
        "symbol",
        "yaml",
        "date",
        "datetime",
        "dateTime",
        "integer",
        "float",
        "double",
        "decimal",
        "boolean",
        "base64Binary",
        "binary",
        "file",
        "array",
    }
)


def gitlab_safe_type(value: str) -> str:
    """A ``type`` that GitLab's converter leaves alone, keeping what the producer said."""
    return f"{value} (producer type)" if value in GITLAB_CONVERTED_TYPES else value


def written_type(value: str, fallback: str = "") -> str:
    """A ``type`` as written: one trimmed line, checked for GitLab after trimming.

    The check must see the final value: ``"yaml "`` written as ``"yaml"`` drops the file.
    """
    return gitlab_safe_type(name_token(value, fallback, TYPE_LIMIT))


def gitlab_safe_types(cases: list[Case]) -> str:
    """Say which types the serialiser will write safely; checked as written: trimmed."""
    found: list[str] = []
    for case in cases:
        items: list[Case | Attempt] = [case, *case.attempts]
        for item in items:
            written = name_token(item.type, "", TYPE_LIMIT)
            if written in GITLAB_CONVERTED_TYPES:
                found.append(written)
                item.type = gitlab_safe_type(written)
    if not found:
        return ""
    kinds = ", ".join(sorted(set(found)))
    return (
        f"{len(found)} type attribute(s) GitLab's XML converter would act on ({kinds}) "
        "were written as '<type> (producer type)'"
    )


def distinct_gitlab_keys(cases: list[Case]) -> str:
    """Rename a case whose GitLab key another case already has; say what was renamed.

    GitLab keys a case by ``"<suite>_<classname>_<name>"`` and keeps one per key, so
    classname ``pkg.a`` + name ``b_c`` and ``pkg.a_b`` + ``c`` would become one case
    there while every other reader shows two. The later one gets a number, visibly.
    """
    keys: set[str] = set()
    pairs = {(case.classname, case.name) for case in cases}
    renamed: list[str] = []
    for case in cases:
        key = f"{case.classname}_{case.name}"
        if key not in keys:
            keys.add(key)
            continue
        number = 2
        while True:
            name = f"{case.name} [{number}]"
            if f"{case.classname}_{name}" not in keys and (case.classname, name) not in pairs:
                break
            number += 1
        renamed.append(f"{case.classname} {case.name!r} as {name!r}")
        case.name = name
        pairs.add((case.classname, name))
        keys.add(f"{case.classname}_{name}")
    if not renamed:
        return ""
    shown = "; ".join(renamed[:5]) + ("; ..." if len(renamed) > 5 else "")
    return (
        f"{len(renamed)} test case(s) renamed whose GitLab key (classname_name) another "
        f"case already had: {shown}"
    )
