"""Choosing what a model is made of, by the data: moves (one class per idea) proposed to a stepwise
search that keeps what lowers the Bayesian information criterion (`nuisance_search`: the nuisance
terms beside a scene's model)."""
