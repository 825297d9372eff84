"""stages.propose.vlm"""
