"""The paper's eight robustness experiments (section 2.3), automated on the headless simulator.

``experiments`` holds the scoring rules and the experiment table as data; ``search`` the outward
range search; ``runner`` executes scenarios in parallel worker processes; ``report`` writes
results.json, the Table 9 / Table 10 Markdown and the plots.
"""
