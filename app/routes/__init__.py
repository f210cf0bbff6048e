"""The REST API under /api, one module per resource."""

from fastapi import APIRouter

from . import animals, calibrations, export, health, jobs, measurements, scans, sessions

api_router = APIRouter()
for module in (health, animals, calibrations, jobs, sessions, scans, measurements, export):
    api_router.include_router(module.router)
