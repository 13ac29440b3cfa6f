"""The outer loop of Sec. 4.6: its options, report and stopping rules, and the one active-set loop both
levels run."""
