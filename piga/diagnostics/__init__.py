"""Sim-to-real gap diagnosis (``piga-diagnose``): where the gap lies, which effect causes it, how far it shrinks."""

from piga.diagnostics.diagnose import DiagnoseConfig, Diagnosis, analyse, diagnose, nominal_of
from piga.diagnostics.observe import DiagnosisInputError, Observations, observe

__all__ = ["DiagnoseConfig", "Diagnosis", "DiagnosisInputError", "Observations", "analyse", "diagnose", "nominal_of", "observe"]
