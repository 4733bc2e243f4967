"""Stage 10: evaluate one controller against the baselines of a study.

``evaluate`` runs what is missing (reusing the baseline study's runs and the
controller's own cached runs) and returns the evaluated part's tables;
``make_card`` writes the one-page population-robustness card (HTML + PNG, its verdict
as JSON and its tables as CSV); ``compare`` puts several controllers' cards side by side
(``compare_table``, pure; ``compare_page.write_comparison`` writes the page and tables).
"""

from .card import Card, card_tables
from .compare import Comparison, compare, compare_table
from .run import BASELINES, Evaluation, evaluate, make_card

__all__ = ["BASELINES", "Card", "Comparison", "Evaluation", "card_tables", "compare",
           "compare_table", "evaluate", "make_card"]
