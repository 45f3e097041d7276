"""compass_sparse"""
