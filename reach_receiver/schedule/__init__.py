"""Schedules: YAML operations lists compiled into checked steps, and their runner."""
