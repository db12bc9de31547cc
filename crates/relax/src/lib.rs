//! Cooperative relaxation of two edge sets by simulated annealing, and the final segmentation.
