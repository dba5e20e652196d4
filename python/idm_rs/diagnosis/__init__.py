"""Diagnosis of a recorded case against its nominal model: calibrate the plausibly-off
parameters, locate the residual (experiment, motion phase, time window), try every catalogue
effect, rank them by BIC and held-out prediction, and give a verdict (a catalogue id, "none" or
"unexplained") with a text report (:mod:`.report`) and figures (:mod:`.plots`)::

    d = idm_rs.diagnose("recordings/dev/dev05")
    d.verdict, d.ranking[0].params
    print(idm_rs.text_report(d))
    idm_rs.plot_diagnosis(d, "plots/")
"""

from .catalogue import CATALOGUE
from .diagnose import diagnose
from .plots import plot_diagnosis
from .report import text_report
from .results import Candidate, Diagnosis

__all__ = ["CATALOGUE", "Candidate", "Diagnosis", "diagnose", "plot_diagnosis", "text_report"]
