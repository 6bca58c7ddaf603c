"""Model-agnostic numerics for autonomous ODEs x' = f(x, p): derivatives, equilibria,
Hopf analysis, periodic orbits and simulation. Nothing in this package knows about maglev."""

from maglev_match.dynamics.system import System

__all__ = ["System"]
