"""Discrepancy discovery: where a measured run and the model's replay of it
disagree, which candidate physical effect explains it, how sure that is,
and the model with it added (docs/discovery.md).

replay (the model open loop on the run's inputs, through the firmware's own
processing) -> candidates (registered physics terms) -> search (GLS on
block means with the model's own noise structure, HAC errors,
Benjamini-Yekutieli across candidates, ambiguity and excitation checks) ->
report (discovery.json, model.toml, report.md, residuals.png); hide
generates runs with a known effect hidden in them.
"""
