"""render.cpu"""
