"""JUnit XML for ``bwdesign check --junit-xml``: one testsuite per stage file."""

from __future__ import annotations

from collections.abc import Sequence
from xml.etree import ElementTree as ET

from .checks import Check

__all__ = ["junit_xml"]


def junit_xml(results: Sequence[tuple[str, list[Check] | str]]) -> str:
    """``results``: per file, its checks or the error that stopped them."""
    suites = ET.Element("testsuites", name="bwdesign check")
    for name, checks in results:
        suite = ET.SubElement(suites, "testsuite", name=name)
        if isinstance(checks, str):
            case = ET.SubElement(suite, "testcase", classname=name, name="stage file")
            ET.SubElement(case, "error", message=checks)
            suite.set("tests", "1")
            suite.set("errors", "1")
            suite.set("failures", "0")
            continue
        fails = 0
        for c in checks:
            case = ET.SubElement(suite, "testcase", classname=name, name=c.name)
            if not c.passed:
                fails += 1
                ET.SubElement(case, "failure", message=c.text).text = c.line()
            else:
                ET.SubElement(case, "system-out").text = c.line()
        suite.set("tests", str(len(checks)))
        suite.set("failures", str(fails))
        suite.set("errors", "0")
    ET.indent(suites)
    # no XML declaration: the file's first line is bwdesign's signature comment (UTF-8)
    return ET.tostring(suites, encoding="unicode") + "\n"
