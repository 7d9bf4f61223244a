"""Learning: K-fold data module, ResGCN model, Lightning module, training driver, reports, prediction."""
