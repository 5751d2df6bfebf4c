"""Sim-to-real gap diagnosis (``piga-diagnose``): where the gap lies, which effect causes it, how far it shrinks."""

from piga.diagnostics.diagnose import DiagnoseConfig, analyse, diagnose
from piga.diagnostics.observe import DiagnosisInputError, Observations, observe
from piga.diagnostics.results import Diagnosis
from piga.io.runs import nominal_of

__all__ = ["DiagnoseConfig", "Diagnosis", "DiagnosisInputError", "Observations", "analyse", "diagnose", "nominal_of", "observe"]
