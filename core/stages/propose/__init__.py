"""stages.propose"""
