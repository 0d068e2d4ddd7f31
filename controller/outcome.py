# TEMPORARY stub (not committed): helper 2 writes the real one
def verdict_line(s):
    return f"{'DELIVERED' if s.get('transported') else 'FAILED'} stub {s.get('goal_error_m')}"


def outcome_table(s):
    return "table"


def next_steps(s, log):
    return [f"fleet replay {log} --plots plots"]
