"""Shared helpers of every report: HTML pages (`html`) and pictures (`figures`).

May import: `fabplan.io`, `fabplan.errors`.
"""
