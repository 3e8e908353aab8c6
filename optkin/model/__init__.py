"""Mechanisms compiled into cached CasADi Functions."""

from .core import Model, clear_cache, get_model

__all__ = ["Model", "clear_cache", "get_model"]
