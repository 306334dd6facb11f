"""greybox"""
