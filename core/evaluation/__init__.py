"""Accuracy of a volume against exact mesh SDFs (paper Table 1 columns): the fixed validation set, its query points,
cached ground truth, metrics, the self-contact split, resource timing, and `volsmpl eval`.

    from volsmpl.evaluation import EvalConfig, evaluate_checkpoint
    res = evaluate_checkpoint(None, EvalConfig(n_bodies=8))     # the shipped VolumetricSMPL checkpoint
    print(format_table(res))
"""
from volsmpl.evaluation.config import PAPER_TABLE1, SAMPLINGS, EvalConfig, EvalResult
from volsmpl.evaluation.points import evaluation_points, part_query_points
from volsmpl.evaluation.run import evaluate, evaluate_checkpoint, evaluate_volume, format_table

__all__ = ["PAPER_TABLE1", "SAMPLINGS", "EvalConfig", "EvalResult", "evaluate", "evaluate_checkpoint",
           "evaluate_volume", "evaluation_points", "format_table", "part_query_points"]
