"""Learning: K-fold data module, ResGCN model, Lightning module, training driver, reports, prediction."""

import warnings

# Lightning's own use of a torch API that torch deprecates, repeated on every fit and in every fold
# process: nothing a user of rheograph can act on
warnings.filterwarnings("ignore", message=r"`isinstance\(treespec, LeafSpec\)` is deprecated")
