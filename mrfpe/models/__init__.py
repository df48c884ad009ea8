"""Declared Markov random fields: graph, states and potentials in; every estimator out."""
