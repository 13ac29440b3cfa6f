"""What is computed on the source hairstyle once: guides (selected or flagged), the kNN sets of Eq. 8-9
and 14, and their compiled k-d tree."""
