"""PDDL 2.1 front end: s-expression reader, abstract syntax and the domain/problem parser."""

from __future__ import annotations

from cbdi_planner.pddl.ast import Domain, Problem
from cbdi_planner.pddl.parser import parse_domain, parse_problem

__all__ = ["Domain", "Problem", "parse_domain", "parse_problem"]
