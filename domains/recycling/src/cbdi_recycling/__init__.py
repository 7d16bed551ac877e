"""cbdi's recycling domain: the paper's robots that recycle plastic litter on a grid.

The PDDL domain, maps, problems, agent files and scenarios sit beside this package in
`domains/recycling/`; the package holds the domain's code that the generic services load
by name: `knowledge.RecyclingKnowledge` (entry point `cbdi.knowledge` `recycling`).
"""
