"""The baselines of the paper's Table I: appearance-based (ORB/SIFT + PnP) and FPFH-ICP."""
