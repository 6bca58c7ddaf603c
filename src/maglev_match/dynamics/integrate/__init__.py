"""Integration in time: ODE runs with events (simulate), periodic responses
of segmented systems (passage) and batched return/collision thresholds
(threshold)."""
