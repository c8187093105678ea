"""External model checkers. Only this package imports stormpy."""
