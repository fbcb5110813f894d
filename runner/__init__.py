"""The haptic-exploration application of bayesprog (touch attention on a surface grid)."""
